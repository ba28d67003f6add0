// Play a trial's clips on a canvas: the example interactions, then the segment.
import {
  LabelLayout,
  agentStyle,
  centreOnAxis,
  drawAgents,
  drawBackground,
  drawPointer,
  drawTrace,
  prepareCanvas,
  publishView,
  viewAt,
} from "./scene.js";

export const STEP_SECONDS = 0.35;
const PAUSE_BETWEEN_CLIPS_MS = 700;

/** True when the participant's system asks for less motion. */
export function prefersReducedMotion() {
  return window.matchMedia("(prefers-reduced-motion: reduce)").matches;
}

function lerp(a, b, f) {
  return a + (b - a) * f;
}

function lerpAngle(a, b, f) {
  const diff = Math.atan2(Math.sin(b - a), Math.cos(b - a));
  return a + diff * f;
}

/** Positions and headings of every agent at fractional step `t` of a clip. */
export function poseAt(clip, t) {
  const last = clip.positions.length - 1;
  const i = Math.max(0, Math.min(last, Math.floor(t)));
  const j = Math.min(last, i + 1);
  const f = Math.max(0, Math.min(1, t - i));
  return clip.positions[i].map((p, agent) => ({
    position: [lerp(p[0], clip.positions[j][agent][0], f), lerp(p[1], clip.positions[j][agent][1], f)],
    heading: clip.headings ? lerpAngle(clip.headings[i][agent], clip.headings[j][agent], f) : null,
  }));
}

/** True when a scene's clips follow the robot (a recorded world) instead of showing it whole
 * (a recorded scene always has a view_span_m > 0: app/data/scene.py RecordedScene). */
export function followsRobot(scene) {
  return Boolean(scene.recorded);
}

/** Pixels per metre that show `view_span_m` across the shorter side of a w x h box. */
function followScale(scene, width, height) {
  return Math.min(width, height) / scene.recorded.view_span_m;
}

/** The view centred on `point` at the follow scale, moved only to stay inside the scene. */
function followView(scene, width, height, point) {
  const scale = followScale(scene, width, height);
  const b = scene.bounds;
  const centre = [
    centreOnAxis(b.x_min_m, b.x_max_m, width, scale, point[0], [point[0], point[0]]),
    centreOnAxis(b.y_min_m, b.y_max_m, height, scale, point[1], [point[1], point[1]]),
  ];
  return viewAt(scale, centre, width, height);
}

/** Draw a clip frame at fractional step `t` (`poses`: the agents' poseAt then), with each
 * agent's trace so far. */
export function drawClipFrame(ctx, view, scene, clip, t, poses = poseAt(clip, t)) {
  drawBackground(ctx, view, scene, t);
  poses.forEach((pose, agent) => {
    const style = agentStyle(scene, agent, clip.sizes);
    const past = clip.positions.slice(0, Math.floor(t) + 1).map((step) => step[agent]);
    drawTrace(ctx, view, style, [...past, pose.position], { dots: true, width: 2 });
  });
  const layout = new LabelLayout(ctx, view.width, view.height);
  drawAgents(ctx, view, poses.map((pose, agent) => ({ style: agentStyle(scene, agent, clip.sizes), ...pose })), layout);
  // the person may be out of a followed view: an arrow points to it (drawPointer draws nothing
  // for a point in view, as the person always is in a whole-scene view: the worlds keep both
  // agents inside the scene's bounds)
  const person = agentStyle(scene, 1);
  drawPointer(ctx, view, poses[1].position, person.tag, person.color, layout);
}

/** The clip list of a trial, each with a caption. */
export function trialClips(trial) {
  const n = trial.examples.length;
  const clips = trial.examples.map((clip, k) => ({ clip, caption: `Example ${k + 1} of ${n}: a full interaction` }));
  clips.push({ clip: trial.segment, caption: "Now: the situation you will predict from" });
  return clips;
}

/**
 * Plays clips in order on one canvas; `play()` resolves when the last clip ends.
 * Calling `play()` again restarts from the first clip (a replay).
 */
export class ClipPlayer {
  constructor(canvas, scene, clips, { onCaption = () => {}, reducedMotion = prefersReducedMotion() } = {}) {
    this.canvas = canvas;
    this.scene = scene;
    this.clips = clips;
    this.onCaption = onCaption;
    this.reducedMotion = reducedMotion;
    this.run = 0;
  }

  /** Play every clip once; resolves true when finished, false when interrupted by stop()/play(). */
  async play() {
    const run = ++this.run;
    for (const { clip, caption } of this.clips) {
      if (run !== this.run) return false;
      this.onCaption(caption);
      const finished = await this.animate(clip, run);
      if (!finished) return false;
      await this.wait(PAUSE_BETWEEN_CLIPS_MS);
    }
    return run === this.run;
  }

  stop() {
    this.run += 1;
  }

  wait(ms) {
    return new Promise((resolve) => setTimeout(resolve, ms));
  }

  /** A frame's view: the whole scene (`fitted`), or the surroundings of the robot at `robot`. */
  frameView(fitted, robot) {
    if (!followsRobot(this.scene)) return fitted;
    const view = followView(this.scene, fitted.width, fitted.height, robot);
    publishView(this.canvas, view);
    return view;
  }

  /** The clip's fractional step after `elapsed` steps' time; with reduced motion the whole
   * step, so each position is shown still for its step's time: the same pace, no gliding. */
  clipStep(steps, elapsed) {
    return Math.min(steps, this.reducedMotion ? Math.floor(elapsed) : elapsed);
  }

  animate(clip, run) {
    let { ctx, view, cssWidth } = prepareCanvas(this.canvas, this.scene);
    const steps = clip.positions.length - 1;
    return new Promise((resolve) => {
      const start = performance.now();
      const frame = (now) => {
        if (run !== this.run) return resolve(false);
        if (this.canvas.parentElement.clientWidth !== cssWidth) {
          ({ ctx, view, cssWidth } = prepareCanvas(this.canvas, this.scene)); // window resized
        }
        const t = this.clipStep(steps, (now - start) / 1000 / STEP_SECONDS);
        const poses = poseAt(clip, t);
        drawClipFrame(ctx, this.frameView(view, poses[0].position), this.scene, clip, t, poses);
        if (t >= steps) return resolve(true);
        requestAnimationFrame(frame);
      };
      requestAnimationFrame(frame);
    });
  }
}
