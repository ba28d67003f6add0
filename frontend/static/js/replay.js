// Replay of one answered trial: the clip through the participant page's own player, then the
// clicks up to a time in the trial, with Ours', the VAE's and the policy's moves over them.
import { MODEL_COLORS, MODEL_LABELS, el } from "./dashboard.js";
import { ClipPlayer, followsRobot, trialClips } from "./player.js";
import { agentStyle, clipToScene, drawAgent, drawBackground, drawClickMarker, drawTrace, prepareCanvas } from "./scene.js";

// a replay's `models` names what it draws: Ours, the VAE, the policy, then the study's plug-in
// predictors (app/researcher/replay.py)
const PLUGIN_DASH = [5, 2, 1, 2];
const CLICK_PLAYBACK_SPEED = 8; // trial milliseconds per wall-clock millisecond
const MODEL_DASH = { ours: [], vae: [7, 4], policy: [2, 3] };
const $ = (id) => document.getElementById(id);

function seconds(ms) {
  return `${(ms / 1000).toFixed(1)} s`;
}

/** A path from `start` through `points` in one model's colour and dash. */
function modelPath(ctx, view, model, start, points) {
  ctx.save();
  ctx.strokeStyle = MODEL_COLORS[model];
  ctx.fillStyle = MODEL_COLORS[model];
  ctx.lineWidth = 2;
  ctx.globalAlpha = 0.9;
  ctx.setLineDash(MODEL_DASH[model] ?? PLUGIN_DASH);
  ctx.beginPath();
  [start, ...points].forEach((p, i) => {
    const [px, py] = view.toPx(p);
    if (i === 0) ctx.moveTo(px, py);
    else ctx.lineTo(px, py);
  });
  ctx.stroke();
  ctx.setLineDash([]);
  for (const p of points) {
    const [px, py] = view.toPx(p);
    ctx.fillRect(px - 2.5, py - 2.5, 5, 5);
  }
  ctx.restore();
}

/**
 * The scene, or a close-up of the `shown` start states' robots, clicks and moves: when one
 * start state is chosen, and for every start state in a scene whose clips follow the robot (a
 * recorded world is too large to show a trial's few metres of answers whole), with the
 * segment and the person then.
 */
function viewScene(replay, shown, closeUp) {
  const { scene, max_step_m: reach, segment, start_states: states } = replay.trial;
  if (!closeUp && !followsRobot(scene)) return scene;
  const points = shown.flatMap((start) => [start.robot, ...start.clicks.map((c) => c.at),
    ...replay.models.flatMap((m) => start.paths[m])]);
  if (!closeUp) points.push(...segment.positions.flat(), ...states.map((s) => s.human));
  const xs = points.map((p) => p[0]);
  const ys = points.map((p) => p[1]);
  const b = scene.bounds;
  const clamp = (v, lo, hi) => Math.min(hi, Math.max(lo, v));
  const bounds = {
    x_min_m: clamp(Math.min(...xs) - reach, b.x_min_m, b.x_max_m), x_max_m: clamp(Math.max(...xs) + reach, b.x_min_m, b.x_max_m),
    y_min_m: clamp(Math.min(...ys) - reach, b.y_min_m, b.y_max_m), y_max_m: clamp(Math.max(...ys) + reach, b.y_min_m, b.y_max_m),
  };
  return { ...scene, bounds };
}

/**
 * Draw the answers as they stood `tMs` into the trial: every start state's robot, the models'
 * moves, and the participant's clicks made by then (numbered in the order made).
 * A pure function of its arguments, so the same time always gives the same picture.
 */
export function drawAnswers(canvas, replay, tMs, only = null) {
  const { trial, starts, click_order: order } = replay;
  const shown = starts.filter((s) => only === null || s.start_index === only);
  const scene = viewScene(replay, shown, only !== null);
  const { ctx, view } = prepareCanvas(canvas, scene);
  const robot = agentStyle(scene, 0, trial.segment.sizes);
  const human = agentStyle(scene, 1, trial.segment.sizes);
  drawBackground(ctx, view, scene);
  ctx.save();
  clipToScene(ctx, view, scene.bounds); // a close-up's traces and agents stop at its edge
  const segment = trial.segment.positions;
  drawTrace(ctx, view, robot, segment.map((s) => s[0]), { alpha: 0.25 });
  drawTrace(ctx, view, human, segment.map((s) => s[1]), { alpha: 0.25 });
  const first = trial.start_states[shown[0]?.start_index ?? 0];
  drawAgent(ctx, view, human, first.human, first.human_heading);
  for (const start of shown) {
    const state = trial.start_states[start.start_index];
    drawAgent(ctx, view, robot, state.robot, state.robot_heading, { alpha: 0.45 });
  }
  const rank = new Map(order.map((c, k) => [`${c.start_index}:${c.step}`, k + 1]));
  let drawn = 0;
  for (const start of shown) {
    const made = start.clicks.filter((c) => c.t_ms <= tMs);
    drawTrace(ctx, view, { color: MODEL_COLORS.human, hatched: false }, [start.robot, ...made.map((c) => c.at)], { alpha: 1, width: 3 });
    for (const click of made) drawClickMarker(ctx, view, click.at, String(rank.get(`${start.start_index}:${click.step}`)));
    drawn += made.length;
  }
  // the models' moves last, over the clicks, so a close match does not hide them
  for (const start of shown) {
    for (const model of replay.models) modelPath(ctx, view, model, start.robot, start.paths[model]);
  }
  ctx.restore();
  canvas.dataset.clicksDrawn = String(drawn);
  return drawn;
}

/** The replay card: a session's trial list, then one trial's clip, clicks and model moves. */
export class ReplayView {
  constructor(loadTrials, loadReplay) {
    this.loadTrials = loadTrials;
    this.loadReplay = loadReplay;
    this.replay = null;
    this.player = null;
    this.run = 0;
    $("replay-play").onclick = () => this.playClip();
    $("replay-clicks").onclick = () => this.playClicks();
    $("replay-all").onclick = () => this.showAt(this.endMs());
    $("replay-time").oninput = () => this.showAt(Number($("replay-time").value), false);
    $("replay-start").onchange = () => this.showAt(Number($("replay-time").value), false);
    window.addEventListener("resize", () => this.replay && !this.player && this.draw());
  }

  /** List a session's answered trials, each with a button that replays it. */
  async openSession(row) {
    $("replay-card").hidden = false;
    $("replay-view").hidden = true;
    $("replay-heading").textContent = `Replay: session ${row.public_id}`;
    const { trials } = await this.loadTrials(row.public_id);
    const head = el("tr", {}, ...["#", "world", "trial", "attention check", "clicks", "undo/reset", "duration", "clip replays", ""]
      .map((t) => el("th", { textContent: t })));
    const body = trials.map((t, i) => {
      const button = el("button", { type: "button", className: "secondary", textContent: "Replay" });
      button.onclick = () => this.openTrial(row.public_id, t.trial_id);
      const check = t.attention_check ? (t.attention_ok ? "passed" : "failed") : "";
      const kind = `${t.is_practice ? "practice " : ""}${t.trial_index + 1} in part ${t.world_position + 1}`;
      const cells = [i + 1, t.world, kind, check, t.clicks, t.history, seconds(t.duration_ms), t.replays];
      return el("tr", { className: "trial-row" }, ...cells.map((c) => el("td", { textContent: String(c) })), el("td", {}, button));
    });
    const table = el("table", { className: "summary" }, el("thead", {}, head), el("tbody", {}, ...body));
    $("replay-trials").replaceChildren(trials.length ? table : el("p", { textContent: "This session answered no trial." }));
    $("replay-card").scrollIntoView({ block: "start" });
  }

  async openTrial(publicId, trialId) {
    this.stop();
    this.replay = await this.loadReplay(publicId, trialId);
    const { response, starts } = this.replay;
    $("replay-view").hidden = false;
    const check = response.attention_check ? `, attention check ${response.attention_ok ? "passed" : "failed"}` : "";
    const kind = `${response.is_practice ? "practice trial" : "trial"} ${response.trial_index + 1} of part ${response.world_position + 1}`;
    $("replay-title").textContent = `Session ${publicId}, ${response.world} ${kind}${check}: answered in ${seconds(response.duration_ms)}, `
      + `clip replayed ${response.replays}×; clip ${this.replay.clip_sha256.slice(0, 12)} verified against the bank.`;
    $("replay-timing").textContent = `Two clocks time each trial. The browser's: ${seconds(response.client_duration_ms)} from the first `
      + `prediction screen to Submit (after the clips). The server's: ${seconds(response.server_duration_ms)} from its answer to the `
      + "previous step to this submission, so it also holds the clips, any pause between trials and the network. "
      + `"Answered in" is the smaller of the two (${seconds(response.duration_ms)}): what the too-fast rule reads, `
      + "so neither clock alone can make a trial look slower than it was.";
    $("replay-start").replaceChildren(el("option", { value: "all", textContent: "all" }),
      ...starts.map((s) => el("option", { value: String(s.start_index), textContent: `${s.start_index + 1} (${s.start_kind})` })));
    const slider = $("replay-time");
    slider.max = String(Math.ceil(this.endMs()));
    $("replay-legend").replaceChildren(...["human", ...this.replay.models].map((m) => {
      const swatch = el("span", { className: "swatch" });
      swatch.style.background = MODEL_COLORS[m];
      return el("span", { className: "legend-item" }, swatch, m === "human" ? "Participant's clicks (numbered in the order made)" : MODEL_LABELS[m]);
    }));
    this.renderTables();
    this.showAt(this.endMs());
  }

  endMs() {
    const last = this.replay.click_order.at(-1)?.t_ms ?? 0;
    return Math.max(last, this.replay.response.client_duration_ms || 0);
  }

  only() {
    const value = $("replay-start").value;
    return value === "all" ? null : Number(value);
  }

  stop() {
    this.run += 1;
    this.player?.stop();
    this.player = null;
  }

  draw() {
    return drawAnswers($("replay-canvas"), this.replay, Number($("replay-time").value), this.only());
  }

  /** Show the answers as they stood `tMs` into the trial. */
  showAt(tMs, stop = true) {
    if (stop) this.stop();
    $("replay-time").value = String(tMs);
    const drawn = this.draw();
    $("replay-time-text").textContent = seconds(Number($("replay-time").value));
    $("replay-caption").textContent = `${drawn} clicks made by ${seconds(tMs)}`;
  }

  /** The clip through the participant page's own player (same code path), then the answers. */
  async playClip() {
    this.stop();
    const { trial } = this.replay;
    this.player = new ClipPlayer($("replay-canvas"), trial.scene, trialClips(trial), {
      onCaption: (text) => { $("replay-caption").textContent = text; },
    });
    const finished = await this.player.play();
    if (finished) this.showAt(0);
  }

  /** Animate the clicks at CLICK_PLAYBACK_SPEED from the trial's start to its end. */
  playClicks() {
    this.stop();
    const run = this.run;
    const end = this.endMs();
    const begin = performance.now();
    const frame = (now) => {
      if (run !== this.run) return;
      const t = Math.min(end, (now - begin) * CLICK_PLAYBACK_SPEED);
      this.showAt(t, false);
      if (t < end) requestAnimationFrame(frame);
    };
    requestAnimationFrame(frame);
  }

  renderTables() {
    const { starts, click_order: order, response } = this.replay;
    const byKey = new Map(starts.flatMap((s) => s.clicks.map((c) => [`${s.start_index}:${c.step}`, [s, c]])));
    const head = el("tr", {}, ...["#", "time", "start state", "step", ...this.replay.models.map((m) => `error ${MODEL_LABELS[m]}`)]
      .map((t) => el("th", { textContent: t })));
    const rows = order.map((o, k) => {
      const [start, click] = byKey.get(`${o.start_index}:${o.step}`);
      const cells = [k + 1, seconds(click.t_ms), `${start.start_index + 1} (${start.start_kind})`, click.step + 1,
        ...this.replay.models.map((m) => start.errors[m][click.step].toFixed(3))];
      return el("tr", {}, ...cells.map((c) => el("td", { textContent: String(c) })));
    });
    $("replay-clicks-count").textContent = `${order.length} clicks, in the order made; error = 1 - cos between the participant's move and the model's.`;
    $("replay-clicks-count").dataset.clicks = String(order.length);
    $("replay-click-table").replaceChildren(el("table", { className: "summary" }, el("thead", {}, head), el("tbody", {}, ...rows)));
    const history = response.history.map((h) => el("li", { textContent: `${seconds(h.t_ms)}: ${h.action} on start state ${h.start_index + 1}` }));
    $("replay-history").replaceChildren(el("h4", { textContent: `Undo and reset presses: ${history.length}` }),
      history.length ? el("ol", {}, ...history) : el("p", { textContent: "none" }));
  }
}
