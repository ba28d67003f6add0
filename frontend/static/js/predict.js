// Prediction input: for each start state the participant places successive robot positions.
import {
  GOAL_COLORS,
  LabelLayout,
  ROBOT_COLOR,
  agentStyle,
  boxAround,
  centreOnAxis,
  clipToScene,
  placeTag,
  drawAgent,
  drawBackground,
  drawPointer,
  drawRing,
  drawTrace,
  fitView,
  preferredHeight,
  publishView,
  sizeCanvas,
  viewAt,
} from "./scene.js";
import { say } from "./words.js";

const KEY_STEP_FRACTION = 0.1; // arrow key moves the cursor by this share of max_step_m
const FINE_FACTOR = 0.25; // with Shift held
const BELOW_CANVAS_PX = 72; // the legend line and the card's padding under the canvas
const MIN_CANVAS_PX = 280;
const VIEW_MARGIN_PX = 24;
// The input device each click records (the server's schemas.ClickInput): a pointer's by its
// pointerType, a stylus counted as touch since it points on the screen as a finger does.
const POINTER_INPUTS = {
  mouse: "mouse",
  touch: "touch",
  pen: "touch",
};
const KEYBOARD_INPUT = "keyboard";
// A start state farther than this from the segment's end is a relocated robot (positions are
// stored to the millimetre)
const RELOCATED_M = 0.01;
// The segment's robot trail where it is not this start's own past (a relocated start, the
// practice feedback), and the person's clicks in the feedback: neither in the robot's colour
const OTHER_PATH_COLOR = "#6b6b6b";
const YOUR_PATH_COLOR = "#111111";

function distance(a, b) {
  return Math.hypot(b[0] - a[0], b[1] - a[1]);
}

function lastHeading(clip, agent) {
  const headings = clip.headings;
  if (headings?.length) return headings[headings.length - 1][agent];
  const p = clip.positions;
  const a = p[p.length - 2]?.[agent] ?? p[0][agent];
  const b = p[p.length - 1][agent];
  return Math.atan2(b[1] - a[1], b[0] - a[0]);
}

/** The input a pointer click came from (a click without a known pointer counts as the mouse's). */
function pointerInput(pointerType) {
  return POINTER_INPUTS[pointerType] ?? POINTER_INPUTS.mouse;
}

function fmt(metres) {
  return `${Number(metres.toFixed(2))} m`;
}

/** CSS height the canvas may take: what is left of the window below its top edge. */
function availableHeight(canvas) {
  const top = canvas.parentElement.getBoundingClientRect().top + window.scrollY;
  return Math.max(MIN_CANVAS_PX, Math.round(window.innerHeight - top - BELOW_CANVAS_PX));
}

/**
 * Collects `steps_to_predict` clicks for each start state of a trial.
 * Calls `onChange(input)` after every change and `onMessage(text, kind)` for feedback.
 * `rules` are the server's for every trial (app/http/routes/pages.py PAGE_RULES
 * `predictions`); a trial's own limits (steps, reach, scene bounds) come with the trial.
 *
 * The view is drawn at the server's scale for this world (`trial.view.px_per_m`,
 * app/prediction_view.py), the same on every screen, around the robot, with the agents at
 * their recorded sizes times the view's `outline_scale` (below 1 in a recorded world, so
 * the first click lands clear of the robot's outline); `overview`, when given, is a canvas
 * that shows the whole scene with the zoomed frame on it.
 */
export class PredictionInput {
  constructor(canvas, trial, { rules, onChange = () => {}, onMessage = () => {}, overview = null }) {
    this.canvas = canvas;
    this.trial = trial;
    this.rules = rules;
    this.scene = trial.scene;
    this.overview = overview;
    this.onChange = onChange;
    this.onMessage = onMessage;
    this.steps = trial.steps_to_predict;
    this.points = trial.start_states.map(() => []);
    this.clickTimes = trial.start_states.map(() => []);
    this.clickInputs = trial.start_states.map(() => []);
    this.history = []; // undo and reset presses, stored with the trial
    this.index = 0;
    this.hover = null;
    this.cursor = null;
    this.cursorMoved = false; // Enter places the cursor only after the arrow keys moved it
    this.showCursor = false;
    this.pointerType = ""; // of the last pointerdown, for a click event that lacks its own
    this.listeners = [];
  }

  /** Take up a saved draft (drafts.py): clicks, times, inputs, history, start state and the clock. */
  restore(draft) {
    this.points = draft.points.map((p) => p.map((q) => [...q]));
    this.clickTimes = draft.click_times_ms.map((t) => [...t]);
    // null: a draft saved by a page from before inputs were recorded; this trial's stay unknown
    this.clickInputs = draft.click_inputs?.map((d) => [...d]) ?? null;
    this.history = [...draft.history];
    this.index = draft.index;
    this.shownAtEpoch = draft.shown_at_ms;
    // click times count from the first showing, through the reload
    this.shownAtPerf = performance.now() - (Date.now() - draft.shown_at_ms);
  }

  /** What a draft keeps of this input (the caller adds trial_id, seq and replays). */
  snapshot() {
    return {
      index: this.index,
      points: this.points,
      click_times_ms: this.clickTimes,
      click_inputs: this.clickInputs,
      history: this.history.slice(-this.rules.history_max_entries),
      shown_at_ms: this.shownAtEpoch,
    };
  }

  /** Clicks placed so far over every start state. */
  clickCount() {
    return this.points.reduce((n, p) => n + p.length, 0);
  }

  /** Show the input (first time: start the clock for click timestamps) and listen to it. */
  start() {
    if (this.shownAtPerf === undefined) {
      this.shownAtPerf = performance.now();
      this.shownAtEpoch = Date.now();
    }
    this.pause();
    this.listen(this.canvas, "pointerdown", (e) => { this.pointerType = e.pointerType; });
    this.listen(this.canvas, "click", (e) => {
      this.place(this.eventPoint(e), pointerInput(e.pointerType || this.pointerType));
    });
    this.listen(this.canvas, "mousemove", (e) => this.setHover(this.eventPoint(e)));
    this.listen(this.canvas, "mouseleave", () => this.setHover(null));
    this.listen(this.canvas, "keydown", (e) => this.handleKey(e));
    this.listen(this.canvas, "focus", () => this.render());
    this.listen(this.canvas, "blur", () => this.render());
    this.listen(window, "resize", () => this.render());
    this.resetCursor();
    this.render();
  }

  /** Stop listening (during a replay the canvas shows the clips); start() resumes. */
  pause() {
    this.destroy();
  }

  /** Detach every listener (the canvas is reused by the next trial). */
  destroy() {
    this.listeners.forEach(([target, type, fn]) => target.removeEventListener(type, fn));
    this.listeners = [];
  }

  listen(target, type, fn) {
    target.addEventListener(type, fn);
    this.listeners.push([target, type, fn]);
  }

  get startState() {
    return this.trial.start_states[this.index];
  }

  get robotHeading() {
    return this.startState.robot_heading ?? lastHeading(this.trial.segment, 0);
  }

  /** True when this start state puts the robot away from where the segment left it. */
  relocated() {
    const end = this.trial.segment.positions.at(-1)[0];
    return distance(end, this.startState.robot) > RELOCATED_M;
  }

  /**
   * The heading the robot is drawn with. At its own segment end, the segment's. Relocated:
   * on a road with lanes the road's direction of travel (the way the segment went along it);
   * on a recorded map the start state's (chosen there within a tolerance of the heading
   * recorded at that spot, app/worlds/recorded.py); a disc none, as the bank keeps no heading
   * of its own for that spot.
   */
  get drawnHeading() {
    if (!this.relocated() || this.scene.recorded) return this.robotHeading;
    if (this.scene.lanes?.length) return Math.cos(this.robotHeading) >= 0 ? 0 : Math.PI;
    return null;
  }

  /** Agent i's style as this view draws it: the segment's recorded size, if any, times the
   * server's outline_scale. */
  agentAt(i) {
    const style = agentStyle(this.scene, i, this.trial.segment.sizes);
    const shrink = this.trial.view?.outline_scale ?? 1;
    return { ...style, length_m: style.length_m * shrink, width_m: style.width_m * shrink };
  }

  get humanHeading() {
    return this.startState.human_heading ?? lastHeading(this.trial.segment, 1);
  }

  get current() {
    return this.points[this.index];
  }

  /** The point the next move starts from: the last click or the start state. */
  anchor() {
    return this.current.length ? this.current[this.current.length - 1] : this.startState.robot;
  }

  stateDone() {
    return this.current.length === this.steps;
  }

  isLast() {
    return this.index === this.trial.start_states.length - 1;
  }

  allDone() {
    return this.points.every((p) => p.length === this.steps);
  }

  eventPoint(event) {
    const rect = this.canvas.getBoundingClientRect();
    const px = event.clientX - rect.left - this.canvas.clientLeft;
    const py = event.clientY - rect.top - this.canvas.clientTop;
    return this.view.toM([px, py]);
  }

  /** Why `point` cannot be the next position, or null when it can. */
  refusal(point) {
    if (this.stateDone()) return `All ${this.steps} positions are placed: press Next, or Undo.`;
    if (!this.insideScene(point)) return "That point is outside the scene.";
    const d = distance(this.anchor(), point);
    if (d < this.trial.min_step_m) {
      return `Too short: a move must be at least ${fmt(this.trial.min_step_m)}; click farther away.`;
    }
    if (d > this.trial.max_step_m * (1 + this.rules.max_step_tolerance)) {
      return `Too far: at most ${fmt(this.trial.max_step_m)} per step; click inside the shaded circle.`;
    }
    return null;
  }

  /** Place `point` as the next position, placed with `input` (POINTER_INPUTS, KEYBOARD_INPUT). */
  place(point, input) {
    const why = this.refusal(point);
    if (why) {
      this.onMessage(why, "error");
      return false;
    }
    this.current.push(point);
    this.clickTimes[this.index].push(this.elapsedMs());
    this.clickInputs?.[this.index].push(input);
    const left = this.steps - this.current.length;
    this.onMessage(left ? `Position ${this.current.length} placed. ${left} to go.` : "All positions placed for this start state.", "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
    return true;
  }

  /** Milliseconds since the input was first shown (what click times are measured in). */
  elapsedMs() {
    return Math.round(performance.now() - this.shownAtPerf);
  }

  undo() {
    if (!this.current.length) return;
    this.history.push({ action: "undo", start_index: this.index, t_ms: this.elapsedMs() });
    this.current.pop();
    this.clickTimes[this.index].pop();
    this.clickInputs?.[this.index].pop();
    this.onMessage("Last position removed.", "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
  }

  reset() {
    this.history.push({ action: "reset", start_index: this.index, t_ms: this.elapsedMs() });
    this.points[this.index] = [];
    this.clickTimes[this.index] = [];
    if (this.clickInputs) this.clickInputs[this.index] = [];
    this.onMessage("Positions for this start state cleared.", "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
  }

  /** Move to the next start state; returns false when this one is not complete. */
  next() {
    if (!this.stateDone() || this.isLast()) return false;
    this.index += 1;
    const where = `Start position ${this.index + 1} of ${this.trial.start_states.length}`;
    this.onMessage(this.relocated()
      ? say("relocated_start", { where })
      : `${where}.`, "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
    return true;
  }

  /** After the trial is answered: show start state `index` with its clicks beside `robot[index]`,
   * the positions the robot reaches from there (the practice payload's `feedback.robot`). */
  review(robot, index) {
    this.truth = robot;
    this.index = index;
    this.render();
  }

  setHover(point) {
    this.hover = point;
    this.render();
  }

  /**
   * The keyboard cursor starts at the robot (the last click or the start state), pointing
   * nowhere: a cursor placed ahead of it would let Enter alone answer constant velocity.
   */
  resetCursor() {
    this.cursor = [...this.anchor()];
    this.cursorMoved = false;
  }

  insideScene([x, y]) {
    const { bounds } = this.scene;
    return x >= bounds.x_min_m && x <= bounds.x_max_m && y >= bounds.y_min_m && y <= bounds.y_max_m;
  }

  handleKey(event) {
    const step = this.trial.max_step_m * KEY_STEP_FRACTION * (event.shiftKey ? FINE_FACTOR : 1);
    const moves = { ArrowLeft: [-step, 0], ArrowRight: [step, 0], ArrowUp: [0, -step], ArrowDown: [0, step] };
    if (moves[event.key]) {
      this.showCursor = true;
      this.cursor = [this.cursor[0] + moves[event.key][0], this.cursor[1] + moves[event.key][1]];
      this.cursorMoved = true;
      this.render();
    } else if (event.key === "Enter" || event.key === " ") {
      this.showCursor = true;
      if (this.stateDone()) this.onChange(this, { confirm: true });
      else if (!this.cursorMoved) this.refuseUnmovedCursor();
      else this.place(this.cursor, KEYBOARD_INPUT);
    } else if (event.key === "Backspace") {
      this.undo();
    } else {
      return;
    }
    event.preventDefault();
  }

  refuseUnmovedCursor() {
    this.onMessage(say("cursor_not_moved"), "error");
    this.render(); // the cross, at the robot
  }

  /** The request body for POST /predictions (submission_id is added by the caller). */
  body(replays) {
    return {
      trial_id: this.trial.trial_id,
      points: this.points,
      click_times_ms: this.clickTimes,
      click_inputs: this.clickInputs,
      shown_at_ms: this.shownAtEpoch,
      submitted_at_ms: Date.now(),
      replays,
      history: this.history.slice(-this.rules.history_max_entries),
    };
  }

  /**
   * The canvas size and view: the server's px per metre (else the whole scene, fitted, as
   * in the instructions' demo), centred a little ahead of the robot and moved only as far as
   * needed to keep the robot's start and the reach of its next move in sight.
   */
  layoutView() {
    const { bounds } = this.scene;
    const width = this.canvas.parentElement.clientWidth;
    const scale = this.trial.view?.px_per_m;
    if (!scale) {
      const height = preferredHeight(bounds, width);
      return { width, height, view: fitView(bounds, width, height) };
    }
    const sceneHeight = (bounds.y_max_m - bounds.y_min_m) * scale + 2 * VIEW_MARGIN_PX;
    const height = Math.round(Math.min(availableHeight(this.canvas), sceneHeight));
    const start = this.startState.robot;
    const lead = this.steps * (this.trial.view.median_step_m ?? 0) / 2;
    const want = [start[0] + lead * Math.cos(this.robotHeading), start[1] + lead * Math.sin(this.robotHeading)];
    const r = this.trial.max_step_m;
    const shown = this.truth ? [...this.current, ...this.truth[this.index]] : [];
    const keep = (axis) => {
      const a = this.anchor()[axis];
      const all = [start[axis], a - r, a + r, ...shown.map((p) => p[axis])];
      return [Math.min(...all), Math.max(...all)];
    };
    const centre = [
      centreOnAxis(bounds.x_min_m, bounds.x_max_m, width, scale, want[0], keep(0)),
      centreOnAxis(bounds.y_min_m, bounds.y_max_m, height, scale, want[1], keep(1)),
    ];
    return { width, height, view: viewAt(scale, centre, width, height) };
  }

  render() {
    const { width, height, view } = this.layoutView();
    const ctx = sizeCanvas(this.canvas, width, height);
    publishView(this.canvas, view);
    this.view = view;
    const scene = this.scene;
    const robot = this.agentAt(0);
    const human = this.agentAt(1);
    const layout = new LabelLayout(ctx, width, height);
    drawBackground(ctx, view, scene);
    const segment = this.trial.segment.positions;
    const ownTrail = !this.relocated() && !this.truth;
    const trail = ownTrail ? robot : { ...robot, color: OTHER_PATH_COLOR };
    drawTrace(ctx, view, trail, segment.map((s) => s[0]), { width: 2, past: true });
    drawTrace(ctx, view, human, segment.map((s) => s[1]), { width: 2 });
    this.drawReach(ctx, view);
    const heading = this.drawnHeading;
    const agents = [
      drawAgent(ctx, view, human, this.startState.human, this.humanHeading, { tag: false }),
      drawAgent(ctx, view, robot, this.startState.robot, heading, { tag: false, seeThrough: true }),
    ];
    agents.forEach((box) => layout.block(box));
    const yours = this.truth ? YOUR_PATH_COLOR : ROBOT_COLOR;
    drawTrace(ctx, view, { ...robot, color: yours }, [this.startState.robot, ...this.current], { width: 3 });
    const rings = this.current.map((point) => drawRing(ctx, view, point, { color: yours }));
    rings.forEach((box) => layout.block(box));
    if (this.truth) this.drawRobotMoves(ctx, view, layout);
    const outOfView = (box) => box.x1 < 0 || box.y1 < 0 || box.x0 > width || box.y0 > height;
    [human, robot].forEach((style, i) => {
      if (!outOfView(agents[i])) placeTag(layout, style, agents[i]); // else an edge arrow points to it
    });
    this.drawNumbers(layout, view);
    this.drawPreview(ctx, view);
    this.drawPointers(ctx, view, layout, outOfView(agents[0]));
    this.canvas.layoutBoxes = { agents, rings, labels: layout.boxes, ownTrail, heading };
    this.drawOverview(view);
  }

  /** The feedback: where the robot goes from this start state, a solid line with a dot per step. */
  drawRobotMoves(ctx, view, layout) {
    const path = [this.startState.robot, ...this.truth[this.index]];
    drawTrace(ctx, view, agentStyle(this.scene, 0), path, { width: 3 });
    ctx.save();
    ctx.fillStyle = ROBOT_COLOR;
    ctx.strokeStyle = "#ffffff";
    ctx.lineWidth = 1.5;
    for (const point of path.slice(1)) {
      const [x, y] = view.toPx(point);
      ctx.beginPath();
      ctx.arc(x, y, 5, 0, 2 * Math.PI);
      ctx.fill();
      ctx.stroke();
      layout.block(boxAround([x, y], 6));
    }
    ctx.restore();
  }

  /** The reach of one step around the last position, cut at the scene's edge. */
  drawReach(ctx, view) {
    if (this.stateDone()) return;
    const [cx, cy] = view.toPx(this.anchor());
    ctx.save();
    clipToScene(ctx, view, this.scene.bounds);
    ctx.fillStyle = ROBOT_COLOR;
    ctx.strokeStyle = ROBOT_COLOR;
    ctx.lineWidth = 1.5;
    ctx.setLineDash([5, 4]);
    ctx.beginPath();
    ctx.arc(cx, cy, this.trial.max_step_m * view.scale, 0, 2 * Math.PI);
    ctx.globalAlpha = 0.1; // a light tint of the robot's colour
    ctx.fill();
    ctx.globalAlpha = 1;
    ctx.stroke();
    ctx.fillStyle = "rgba(60, 60, 60, 0.35)";
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.arc(cx, cy, Math.max(this.trial.min_step_m * view.scale, 1), 0, 2 * Math.PI);
    ctx.fill();
    ctx.restore();
  }

  /** Each click's number beside its ring, off the path and clear of agents and other labels. */
  drawNumbers(layout, view) {
    const path = [this.startState.robot, ...this.current];
    this.current.forEach((point, k) => {
      const [ax, ay] = view.toPx(path[k]);
      const [px, py] = view.toPx(point);
      const along = Math.atan2(py - ay, px - ax);
      layout.place(String(k + 1), [px, py], 17, { color: "#111111", angles: [along - Math.PI / 2, along + Math.PI / 2] });
    });
  }

  /** Arrows at the canvas edge towards the other agent, by its tag (when none of it is in view: a part in view
   * carries its own tag) and the goals the zoomed view leaves out. */
  drawPointers(ctx, view, layout, humanOutOfView) {
    const human = agentStyle(this.scene, 1);
    if (humanOutOfView) drawPointer(ctx, view, this.startState.human, human.tag, human.color, layout);
    (this.scene.goals || []).forEach((goal, k) => {
      drawPointer(ctx, view, [goal.x_m, goal.y_m], goal.label || `goal ${k + 1}`, GOAL_COLORS[k % GOAL_COLORS.length], layout);
    });
  }

  /** The whole scene, small, with the robot, the person and the zoomed frame. */
  drawOverview(view) {
    const canvas = this.overview;
    if (!canvas || !canvas.parentElement || !this.trial.view) return;
    const { bounds } = this.scene;
    const width = canvas.parentElement.clientWidth;
    const aspect = (bounds.y_max_m - bounds.y_min_m) / (bounds.x_max_m - bounds.x_min_m);
    const height = Math.max(40, Math.round((width - 8) * aspect + 8));
    const ctx = sizeCanvas(canvas, width, height);
    const small = fitView(bounds, width, height, 4);
    drawBackground(ctx, small, this.scene, 0, { labels: false });
    const dot = (point, color) => {
      const [x, y] = small.toPx(point);
      ctx.fillStyle = color;
      ctx.beginPath();
      ctx.arc(x, y, 4, 0, 2 * Math.PI);
      ctx.fill();
    };
    dot(this.startState.human, agentStyle(this.scene, 1).color);
    dot(this.startState.robot, ROBOT_COLOR);
    const [x0, y0] = small.toPx(view.toM([0, 0]));
    const [x1, y1] = small.toPx(view.toM([view.width, view.height]));
    ctx.strokeStyle = "#111111";
    ctx.lineWidth = 1.5;
    ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
  }

  drawPreview(ctx, view) {
    if (this.stateDone()) return;
    const target = this.showCursor && document.activeElement === this.canvas ? this.cursor : this.hover;
    if (!target) return;
    const ok = !this.refusal(target);
    const [ax, ay] = view.toPx(this.anchor());
    const [tx, ty] = view.toPx(target);
    ctx.save();
    ctx.strokeStyle = ok ? ROBOT_COLOR : "#6b6b6b";
    ctx.lineWidth = 2;
    ctx.setLineDash([4, 4]);
    ctx.beginPath();
    ctx.moveTo(ax, ay);
    ctx.lineTo(tx, ty);
    ctx.stroke();
    ctx.setLineDash([]);
    ctx.lineWidth = 2;
    ctx.beginPath(); // crosshair
    ctx.moveTo(tx - 8, ty);
    ctx.lineTo(tx + 8, ty);
    ctx.moveTo(tx, ty - 8);
    ctx.lineTo(tx, ty + 8);
    ctx.stroke();
    if (!ok) {
      ctx.beginPath(); // a cross-out for a refused spot, so it is not shown by colour alone
      ctx.moveTo(tx - 6, ty - 6);
      ctx.lineTo(tx + 6, ty + 6);
      ctx.moveTo(tx + 6, ty - 6);
      ctx.lineTo(tx - 6, ty + 6);
      ctx.stroke();
    }
    ctx.restore();
  }
}
