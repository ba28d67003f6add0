// The instructions' animated demo: a neutral illustration (not study data) of a clip and of
// placing three predicted positions from several start positions (the robot's own, then
// moved elsewhere), drawn with the same code as the real trials. The study names which
// (app/study/words.py DemoName): `obstacle`, a disc robot and a person on a field, or `road`,
// two cars on a drawn road; its captions are the study's words (words.js).
import { ClipPlayer, prefersReducedMotion } from "./player.js";
import { PredictionInput } from "./predict.js";
import { say } from "./words.js";

const DEMO_STEPS = 8;
const SEGMENT_STEPS = 5; // the clip's first steps are the segment predicted from
const CLICK_INTERVAL_MS = 900;
const NEXT_START_MS = 1400;

/** The headings of every agent along `positions` (each step's direction of travel). */
function headingsOf(positions) {
  return positions.map((_, t) => {
    const a = positions[Math.max(0, t - 1)];
    const b = positions[Math.max(1, t)];
    return [0, 1].map((i) => Math.atan2(b[i][1] - a[i][1], b[i][0] - a[i][0]));
  });
}

/** A clip of DEMO_STEPS steps: `robotAt(f)` and `humanAt(f)` give each agent's place at f in [0, 1]. */
function clipAlong(robotAt, humanAt) {
  const positions = [];
  for (let t = 0; t <= DEMO_STEPS; t += 1) positions.push([robotAt(t / DEMO_STEPS), humanAt(t / DEMO_STEPS)]);
  return { positions, headings: headingsOf(positions) };
}

/** Three clicks from `start` along the unit vector `unit`, `stepM` apart. */
function clicksAlong(start, unit, stepM) {
  return [1, 2, 3].map((k) => [start[0] + k * stepM * unit[0], start[1] + k * stepM * unit[1]]);
}

// ---- obstacle: a disc robot curving around an obstacle towards goal A while the person walks left
const GOAL = [11, 1]; // goal A: the demo's clicks head there from every start

const OBSTACLE_DEMO = {
  scene: {
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
  },
  clip: () => clipAlong(
    (f) => [1 + 8 * f, 4.5 - 2.6 * Math.sin(f * Math.PI * 0.6)],
    (f) => [10.5 - 4 * f, 5.2],
  ),
  // where the robot is moved to after its own start (clear of the obstacle and the person),
  // with the segment's heading (null)
  movedStarts: [{ at: [3, 1.2], heading: null }, { at: [8.8, 3.9], heading: null }],
  /** Three clicks from `start` straight towards goal A, 1 m apart. */
  clicks: (start) => {
    const d = Math.hypot(GOAL[0] - start[0], GOAL[1] - start[1]);
    return clicksAlong(start, [(GOAL[0] - start[0]) / d, (GOAL[1] - start[1]) / d], 1.0);
  },
  limits: { max_step_m: 1.6, min_step_m: 0.2 },
};

// ---- road: a blue car driving east in its lane, an oncoming car, and a side road to the south
// Cars keep right: eastbound in the lower lane, southbound in the side road's western lane.
// The map is drawn as a recorded scene's is (a driven band, kerbs, dashed lane lines).
const ROAD = { x0: 0, x1: 44, top: 3, middle: 6.5, bottom: 10, sideWest: 26, sideMiddle: 29.5, sideEast: 33, end: 26 };
const ROAD_CELL_M = 0.5;
const EAST_LANE_Y = (ROAD.middle + ROAD.bottom) / 2;
const WEST_LANE_Y = (ROAD.top + ROAD.middle) / 2;
const SOUTH_LANE_X = (ROAD.sideWest + ROAD.sideMiddle) / 2;
const CAR_STEP_M = 3.5; // one demo step (0.5 s) at about 25 km/h

/** The driven area of rectangles [x0, y0, x1, y1] (m) as app/data/scene.py DrivenArea runs. */
function drivenRuns(rects) {
  const runs = [];
  const rows = Math.round(ROAD.end / ROAD_CELL_M);
  for (let row = 0; row < rows; row += 1) {
    const y = (row + 0.5) * ROAD_CELL_M;
    for (const [x0, y0, x1, y1] of rects) {
      if (y > y0 && y < y1) runs.push([row, Math.round(x0 / ROAD_CELL_M), Math.round(x1 / ROAD_CELL_M) - 1]);
    }
  }
  return { cell_m: ROAD_CELL_M, x0_m: 0, y0_m: 0, runs };
}

function line(kind, points, dashed = false) {
  return { kind, dashed, points };
}

const ROAD_DEMO = {
  scene: {
    world: "demo",
    dt_s: 0.5,
    frame: "illustration",
    bounds: { x_min_m: ROAD.x0, x_max_m: ROAD.x1, y_min_m: 0, y_max_m: ROAD.end },
    lanes: [],
    obstacles: [],
    goals: [],
    agents: [
      { name: "robot", kind: "car", length_m: 4.6, width_m: 1.9 },
      { name: "human", kind: "car", length_m: 4.6, width_m: 1.9 },
    ],
    recorded: {
      source: "illustration",
      view_span_m: ROAD.end,
      driven: drivenRuns([[ROAD.x0, ROAD.top, ROAD.x1, ROAD.bottom],
        [ROAD.sideWest, ROAD.bottom - 1, ROAD.sideEast, ROAD.end]]),
      lines: [
        line("kerb", [[ROAD.x0, ROAD.top], [ROAD.x1, ROAD.top]]),
        line("kerb", [[ROAD.x0, ROAD.bottom], [ROAD.sideWest, ROAD.bottom], [ROAD.sideWest, ROAD.end]]),
        line("kerb", [[ROAD.x1, ROAD.bottom], [ROAD.sideEast, ROAD.bottom], [ROAD.sideEast, ROAD.end]]),
        line("border", [[ROAD.x0, ROAD.middle], [ROAD.x1, ROAD.middle]], true),
        line("border", [[ROAD.sideMiddle, ROAD.bottom + 1], [ROAD.sideMiddle, ROAD.end]], true),
      ],
    },
  },
  clip: () => clipAlong(
    (f) => [3 + f * DEMO_STEPS * CAR_STEP_M, EAST_LANE_Y],
    (f) => [40 - f * DEMO_STEPS * 3, WEST_LANE_Y],
  ),
  // the blue car moved back in its lane, and into the side road's lane, heading south
  movedStarts: [{ at: [8, EAST_LANE_Y], heading: 0 }, { at: [SOUTH_LANE_X, ROAD.bottom + 2], heading: Math.PI / 2 }],
  /** Three clicks from `start` along its lane (the way the car there heads), one step apart. */
  clicks: (start, heading) => clicksAlong(start, [Math.cos(heading), Math.sin(heading)], CAR_STEP_M),
  limits: { max_step_m: 5.5, min_step_m: 0.5 },
};

const DEMOS = { obstacle: OBSTACLE_DEMO, road: ROAD_DEMO };

function wait(ms) {
  return new Promise((resolve) => setTimeout(resolve, ms));
}

/** The demo's trial: the clip's first steps as the segment, its own end and the moved starts. */
function demoTrial(demo, clip) {
  const segment = {
    positions: clip.positions.slice(0, SEGMENT_STEPS + 1),
    headings: clip.headings.slice(0, SEGMENT_STEPS + 1),
  };
  const [robot, human] = segment.positions[SEGMENT_STEPS];
  const [robotHeading, humanHeading] = segment.headings[SEGMENT_STEPS];
  const state = (at, heading) => ({ robot: at, human, robot_heading: heading ?? robotHeading, human_heading: humanHeading });
  return {
    trial_id: "demo", scene: demo.scene, segment, steps_to_predict: 3,
    start_states: [state(robot, null), ...demo.movedStarts.map(({ at, heading }) => state(at, heading))],
    ...demo.limits,
  };
}

/** Plays the illustration `name` (a key of DEMOS) once: a clip, then three clicks from each
 * start position (`rules` as PredictionInput takes them). */
export class InstructionsDemo {
  constructor(canvas, name, { rules, onCaption = () => {} }) {
    this.demo = DEMOS[name];
    if (!this.demo) throw new Error(`no demo ${name}`);
    this.canvas = canvas;
    this.rules = rules;
    this.onCaption = onCaption;
    this.clip = this.demo.clip();
    this.player = new ClipPlayer(canvas, this.demo.scene, [{ clip: this.clip, caption: say("demo_clip") }], { onCaption });
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
    const trial = demoTrial(this.demo, this.clip);
    const input = new PredictionInput(this.canvas, trial, { rules: this.rules, onMessage: () => {} });
    input.shownAtPerf = performance.now();
    const n = trial.start_states.length;
    for (let k = 0; k < n; k += 1) {
      if (k) {
        await wait(prefersReducedMotion() ? 600 : NEXT_START_MS);
        if (run !== this.run) return;
        input.next();
      }
      this.onCaption(k ? say("demo_moved_start", { k: k + 1, n }) : say("demo_own_start", { n }));
      input.render();
      const start = trial.start_states[k];
      for (const point of this.demo.clicks(start.robot, start.robot_heading)) {
        await wait(prefersReducedMotion() ? 300 : CLICK_INTERVAL_MS);
        if (run !== this.run) return;
        input.place(point, "mouse");
      }
    }
    this.canvas.dataset.demoStarts = String(n); // how many start positions it showed
    this.onCaption("In the study you press Next after each start position, and Submit after the last");
  }
}
