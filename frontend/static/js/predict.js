// Prediction input: for each start state the participant places successive robot positions.
import { ROBOT_COLOR, agentStyle, drawAgent, drawBackground, drawClickMarker, drawTrace, prepareCanvas } from "./scene.js";

const KEY_STEP_FRACTION = 0.1; // arrow key moves the cursor by this share of max_step_m
const FINE_FACTOR = 0.25; // with Shift held

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

function fmt(metres) {
  return `${Number(metres.toFixed(2))} m`;
}

/**
 * Collects `steps_to_predict` clicks for each start state of a trial.
 * Calls `onChange(input)` after every change and `onMessage(text, kind)` for feedback.
 */
export class PredictionInput {
  constructor(canvas, trial, { onChange = () => {}, onMessage = () => {} } = {}) {
    this.canvas = canvas;
    this.trial = trial;
    this.scene = trial.scene;
    this.onChange = onChange;
    this.onMessage = onMessage;
    this.steps = trial.steps_to_predict;
    this.points = trial.start_states.map(() => []);
    this.clickTimes = trial.start_states.map(() => []);
    this.history = []; // undo and reset presses, stored with the trial
    this.index = 0;
    this.hover = null;
    this.cursor = null;
    this.showCursor = false;
    this.listeners = [];
  }

  /** Show the input (first time: start the clock for click timestamps) and listen to it. */
  start() {
    if (this.shownAtPerf === undefined) {
      this.shownAtPerf = performance.now();
      this.shownAtEpoch = Date.now();
    }
    this.pause();
    this.listen(this.canvas, "click", (e) => this.place(this.eventPoint(e)));
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
    if (d > this.trial.max_step_m) {
      return `Too far: at most ${fmt(this.trial.max_step_m)} per step; click inside the shaded circle.`;
    }
    return null;
  }

  place(point) {
    const why = this.refusal(point);
    if (why) {
      this.onMessage(why, "error");
      return false;
    }
    this.current.push(point);
    this.clickTimes[this.index].push(this.elapsedMs());
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
    this.onMessage("Last position removed.", "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
  }

  reset() {
    this.history.push({ action: "reset", start_index: this.index, t_ms: this.elapsedMs() });
    this.points[this.index] = [];
    this.clickTimes[this.index] = [];
    this.onMessage("Positions for this start state cleared.", "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
  }

  /** Move to the next start state; returns false when this one is not complete. */
  next() {
    if (!this.stateDone() || this.isLast()) return false;
    this.index += 1;
    this.onMessage(`Start state ${this.index + 1} of ${this.trial.start_states.length}.`, "ok");
    this.resetCursor();
    this.render();
    this.onChange(this);
    return true;
  }

  setHover(point) {
    this.hover = point;
    this.render();
  }

  /** Keyboard cursor starts one mid-length move ahead along the robot's current direction. */
  resetCursor() {
    const anchor = this.anchor();
    const n = this.current.length;
    const prev = n >= 2 ? this.current[n - 2] : this.startState.robot;
    const heading = n ? Math.atan2(anchor[1] - prev[1], anchor[0] - prev[0]) : this.robotHeading;
    const reach = (this.trial.min_step_m + this.trial.max_step_m) / 2;
    const ahead = (angle) => [anchor[0] + reach * Math.cos(angle), anchor[1] + reach * Math.sin(angle)];
    // Straight ahead, or the nearest turn that stays inside the scene.
    const turns = [0, 1, -1, 2, -2, 3, -3, 4, -4, 5, -5, 6].map((k) => (k * Math.PI) / 6);
    const inside = turns.map((turn) => ahead(heading + turn)).find((p) => this.insideScene(p));
    this.cursor = inside ?? ahead(heading);
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
      this.render();
    } else if (event.key === "Enter" || event.key === " ") {
      this.showCursor = true;
      if (this.stateDone()) this.onChange(this, { confirm: true });
      else this.place(this.cursor);
    } else if (event.key === "Backspace") {
      this.undo();
    } else {
      return;
    }
    event.preventDefault();
  }

  /** The request body for POST /predictions (submission_id is added by the caller). */
  body(replays) {
    return {
      trial_id: this.trial.trial_id,
      points: this.points,
      click_times_ms: this.clickTimes,
      shown_at_ms: this.shownAtEpoch,
      submitted_at_ms: Date.now(),
      replays,
      history: this.history.slice(-500),
    };
  }

  render() {
    const { ctx, view } = prepareCanvas(this.canvas, this.scene);
    this.view = view;
    const scene = this.scene;
    const robot = agentStyle(scene, 0);
    const human = agentStyle(scene, 1);
    drawBackground(ctx, view, scene);
    const segment = this.trial.segment.positions;
    drawTrace(ctx, view, robot, segment.map((s) => s[0]), { alpha: 0.25 });
    drawTrace(ctx, view, human, segment.map((s) => s[1]), { alpha: 0.25 });
    drawAgent(ctx, view, human, this.startState.human, this.humanHeading);
    this.drawRobots(ctx, view, robot);
    this.drawReach(ctx, view);
    drawTrace(ctx, view, robot, [this.startState.robot, ...this.current], { alpha: 1, width: 3 });
    this.drawPreview(ctx, view);
    this.drawMarkers(ctx, view);
  }

  /** The robot at its start state, and (fainter) where the last click puts it. */
  drawRobots(ctx, view, robot) {
    drawAgent(ctx, view, robot, this.startState.robot, this.robotHeading, { alpha: this.current.length ? 0.4 : 1 });
    if (!this.current.length) return;
    const [a, b] = [this.startState.robot, ...this.current].slice(-2);
    drawAgent(ctx, view, robot, b, Math.atan2(b[1] - a[1], b[0] - a[0]), { alpha: 0.6 });
  }

  drawReach(ctx, view) {
    if (this.stateDone()) return;
    const [cx, cy] = view.toPx(this.anchor());
    ctx.save();
    ctx.fillStyle = "rgba(0, 114, 178, 0.12)";
    ctx.strokeStyle = ROBOT_COLOR;
    ctx.lineWidth = 1.5;
    ctx.setLineDash([5, 4]);
    ctx.beginPath();
    ctx.arc(cx, cy, this.trial.max_step_m * view.scale, 0, 2 * Math.PI);
    ctx.fill();
    ctx.stroke();
    ctx.fillStyle = "rgba(60, 60, 60, 0.35)";
    ctx.setLineDash([]);
    ctx.beginPath();
    ctx.arc(cx, cy, Math.max(this.trial.min_step_m * view.scale, 1), 0, 2 * Math.PI);
    ctx.fill();
    ctx.restore();
  }

  /** Numbered markers on the clicked positions, drawn last so nothing hides them. */
  drawMarkers(ctx, view) {
    this.current.forEach((point, k) => {
      drawClickMarker(ctx, view, point, String(k + 1), { stroke: ROBOT_COLOR, radius: 9 });
    });
  }

  drawPreview(ctx, view) {
    if (this.stateDone()) return;
    const target = this.showCursor && document.activeElement === this.canvas ? this.cursor : this.hover;
    if (!target) return;
    const ok = !this.refusal(target);
    const [ax, ay] = view.toPx(this.anchor());
    const [tx, ty] = view.toPx(target);
    ctx.save();
    ctx.strokeStyle = ok ? ROBOT_COLOR : "#8a8a8a";
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
