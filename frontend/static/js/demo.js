// The instructions' animated demo: a neutral illustration (not study data) of a clip and of
// placing three predicted positions from several start positions (the robot's own, then
// moved elsewhere), drawn with the same code as the real trials.
import { ClipPlayer, prefersReducedMotion } from "./player.js";
import { PredictionInput } from "./predict.js";

const DEMO_STEPS = 8;
const SEGMENT_STEPS = 5; // the clip's first steps are the segment predicted from
const CLICK_INTERVAL_MS = 900;
const NEXT_START_MS = 1400;
const CLICK_STEP_M = 1.0;
const GOAL = [11, 1]; // goal A: the demo's clicks head there from every start
// where the robot is moved to after its own start (clear of the obstacle and the person)
const MOVED_STARTS = [[3, 1.2], [8.8, 3.9]];

const DEMO_SCENE = {
  world: "demo",
  dt_s: 0.5,
  frame: "illustration",
  bounds: { x_min_m: 0, x_max_m: 12, y_min_m: 0, y_max_m: 6 },
  lanes: [],
  obstacles: [{ x_m: 6, y_m: 3.9, radius_m: 0.7, label: "" }],
  goals: [
    { x_m: 11, y_m: 1, radius_m: 0.6, label: "goal A" },
    { x_m: 11, y_m: 5, radius_m: 0.6, label: "goal B" },
  ],
  agents: [
    { name: "robot", kind: "disc", length_m: 0.6, width_m: 0.6 },
    { name: "human", kind: "disc", length_m: 0.6, width_m: 0.6 },
  ],
};

/** A robot curving around the obstacle towards goal A while the person walks left. */
function demoClip() {
  const positions = [];
  const headings = [];
  for (let t = 0; t <= DEMO_STEPS; t += 1) {
    const f = t / DEMO_STEPS;
    const robot = [1 + 8 * f, 4.5 - 2.6 * Math.sin(f * Math.PI * 0.6)];
    const human = [10.5 - 4 * f, 5.2];
    positions.push([robot, human]);
  }
  for (let t = 0; t <= DEMO_STEPS; t += 1) {
    const a = positions[Math.max(0, t - 1)];
    const b = positions[Math.max(1, t)];
    headings.push([0, 1].map((i) => Math.atan2(b[i][1] - a[i][1], b[i][0] - a[i][0])));
  }
  return { positions, headings };
}

function wait(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

/** Three clicks from `start` straight towards goal A, CLICK_STEP_M apart. */
function clicksTowardsGoal(start) {
  const d = Math.hypot(GOAL[0] - start[0], GOAL[1] - start[1]);
  const unit = [(GOAL[0] - start[0]) / d, (GOAL[1] - start[1]) / d];
  return [1, 2, 3].map((k) => [start[0] + k * CLICK_STEP_M * unit[0], start[1] + k * CLICK_STEP_M * unit[1]]);
}

/** The demo's trial: the clip's first steps as the segment, its own end and MOVED_STARTS. */
function demoTrial(clip) {
  const segment = {
    positions: clip.positions.slice(0, SEGMENT_STEPS + 1),
    headings: clip.headings.slice(0, SEGMENT_STEPS + 1),
  };
  const [robot, human] = segment.positions[SEGMENT_STEPS];
  const [robotHeading, humanHeading] = segment.headings[SEGMENT_STEPS];
  const state = (at) => ({ robot: at, human, robot_heading: robotHeading, human_heading: humanHeading });
  return {
    trial_id: "demo", scene: DEMO_SCENE, segment, steps_to_predict: 3,
    start_states: [state(robot), ...MOVED_STARTS.map(state)],
    max_step_m: 1.6, min_step_m: 0.2,
  };
}

/** Plays the illustration once: a clip, then three clicks from each start position (`rules` as
 * PredictionInput takes them). */
export class InstructionsDemo {
  constructor(canvas, { rules, onCaption = () => {} }) {
    this.canvas = canvas;
    this.rules = rules;
    this.onCaption = onCaption;
    this.clip = demoClip();
    this.player = new ClipPlayer(canvas, DEMO_SCENE, [
      { clip: this.clip, caption: "Illustration: a clip shows the robot (R) and the person (H) moving" },
    ], { onCaption });
    this.run = 0;
  }

  stop() {
    this.run += 1;
    this.player.stop();
  }

  async play() {
    const run = ++this.run;
    delete this.canvas.dataset.demoStarts;
    if (!(await this.player.play()) || run !== this.run) return;
    const trial = demoTrial(this.clip);
    const input = new PredictionInput(this.canvas, trial, { rules: this.rules, onMessage: () => {} });
    input.shownAtPerf = performance.now();
    const starts = trial.start_states.length;
    for (let k = 0; k < starts; k += 1) {
      if (k) {
        await wait(prefersReducedMotion() ? 600 : NEXT_START_MS);
        if (run !== this.run) return;
        input.next();
      }
      this.onCaption(k
        ? `Start position ${k + 1} of ${starts}: the robot is moved elsewhere (its path in the clip is grey); predict from there`
        : `Start position 1 of ${starts}: where the clip ended. Click where the robot will be after each of the next steps, inside the shaded circle`);
      input.render();
      for (const point of clicksTowardsGoal(trial.start_states[k].robot)) {
        await wait(prefersReducedMotion() ? 300 : CLICK_INTERVAL_MS);
        if (run !== this.run) return;
        input.place(point, "mouse");
      }
    }
    this.canvas.dataset.demoStarts = String(starts); // how many start positions it showed
    this.onCaption("In the study you press Next after each start position, and Submit after the last");
  }
}
