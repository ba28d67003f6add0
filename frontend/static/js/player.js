// Play a trial's clips on a canvas: the example interactions, then the segment.
import { LabelLayout, agentStyle, drawAgents, drawBackground, drawTrace, prepareCanvas } from "./scene.js";

export const STEP_SECONDS = 0.35;
const PAUSE_BETWEEN_CLIPS_MS = 700;
const REDUCED_MOTION_HOLD_MS = 1800;

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

/** Draw a clip frame at fractional step `t`, with each agent's trace so far. */
export function drawClipFrame(ctx, view, scene, clip, t) {
  drawBackground(ctx, view, scene, t);
  const poses = poseAt(clip, t);
  poses.forEach((pose, agent) => {
    const style = agentStyle(scene, agent);
    const past = clip.positions.slice(0, Math.floor(t) + 1).map((step) => step[agent]);
    drawTrace(ctx, view, style, [...past, pose.position], { dots: true, width: 2 });
  });
  const layout = new LabelLayout(ctx, view.width, view.height);
  drawAgents(ctx, view, poses.map((pose, agent) => ({ style: agentStyle(scene, agent), ...pose })), layout);
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
      const finished = this.reducedMotion ? await this.showStill(clip, run) : await this.animate(clip, run);
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

  /** Reduced motion: the final frame with the whole path, held still. */
  async showStill(clip, run) {
    const { ctx, view } = prepareCanvas(this.canvas, this.scene);
    drawClipFrame(ctx, view, this.scene, clip, clip.positions.length - 1);
    await this.wait(REDUCED_MOTION_HOLD_MS);
    return run === this.run;
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
        const t = Math.min(steps, (now - start) / 1000 / STEP_SECONDS);
        drawClipFrame(ctx, view, this.scene, clip, t);
        if (t >= steps) return resolve(true);
        requestAnimationFrame(frame);
      };
      requestAnimationFrame(frame);
    });
  }
}
