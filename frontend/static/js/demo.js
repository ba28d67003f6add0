// The instructions' animated demo: a neutral illustration (not study data) of a clip
// and of placing three predicted positions, drawn with the same code as the real trials.
import { ClipPlayer, prefersReducedMotion } from "./player.js";
import { PredictionInput } from "./predict.js";

const DEMO_STEPS = 8;
const CLICK_INTERVAL_MS = 900;

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

/** Plays the illustration once: a clip, then three clicks from a start state (`rules` as PredictionInput takes them). */
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
    if (!(await this.player.play()) || run !== this.run) return;
    const end = this.clip.positions[DEMO_STEPS];
    const trial = {
      trial_id: "demo", scene: DEMO_SCENE, segment: this.clip, steps_to_predict: 3,
      start_states: [{ robot: this.clip.positions[5][0], human: end[1] }],
      max_step_m: 1.6, min_step_m: 0.2,
    };
    const input = new PredictionInput(this.canvas, trial, { rules: this.rules, onMessage: () => {} });
    input.shownAtPerf = performance.now();
    this.onCaption("Then you click where the robot will be after each of the next steps, inside the shaded circle");
    input.render();
    const start = trial.start_states[0].robot;
    const clicks = [[start[0] + 1.2, start[1] - 0.6], [start[0] + 2.4, start[1] - 1.0], [start[0] + 3.6, start[1] - 1.2]];
    for (const point of clicks) {
      await wait(prefersReducedMotion() ? 300 : CLICK_INTERVAL_MS);
      if (run !== this.run) return;
      input.place(point);
    }
    this.onCaption("Positions placed: in the study you then press Next (or Submit after the last start position)");
  }
}
