// Researcher dashboard views: sessions table, study versions, error plots (SVG), field panels.
import { drawBackground, prepareCanvas } from "./scene.js";

// The analysis' figures' names and colours (app/core/contracts.py), as the page carries them;
// a study's plug-in predictors arrive with its alignment summary (useStyle).
const MODEL_STYLE = JSON.parse(document.getElementById("model-style").textContent);
export const MODEL_COLORS = MODEL_STYLE.colors;
export const MODEL_LABELS = MODEL_STYLE.labels;

/** Add the colours and labels the dashboard's JSON gives (every predictor of the study). */
function useStyle(style) {
  Object.assign(MODEL_COLORS, style.colors);
  Object.assign(MODEL_LABELS, style.labels);
}
const SVG = "http://www.w3.org/2000/svg";

export function el(tag, props = {}, ...children) {
  const node = Object.assign(document.createElement(tag), props);
  node.append(...children);
  return node;
}

function svg(tag, attrs = {}, text = null) {
  const node = document.createElementNS(SVG, tag);
  for (const [k, v] of Object.entries(attrs)) node.setAttribute(k, String(v));
  if (text !== null) node.textContent = text;
  return node;
}

function num(value, digits = 3) {
  return value === null || value === undefined ? "–" : Number(value).toFixed(digits);
}

/** Month-day hours:minutes in the researcher's time zone. */
function when(iso) {
  if (!iso) return "–";
  const d = new Date(iso);
  const pad = (n) => String(n).padStart(2, "0");
  return `${pad(d.getMonth() + 1)}-${pad(d.getDate())} ${pad(d.getHours())}:${pad(d.getMinutes())}`;
}

function duration(seconds) {
  if (seconds < 90) return `${seconds.toFixed(0)} s`;
  return `${Math.floor(seconds / 60)} min ${String(Math.round(seconds % 60)).padStart(2, "0")} s`;
}

function attentionText({ failed, seen }) {
  if (!seen) return "none seen";
  return `${failed} of ${seen}${failed ? ": review" : ""}`;
}

const STATUS_TEXT = { awaiting_consent: "at consent", in_progress: "in progress", stale: "stale", ended: "ended", replaced: "replaced" };

// Each column: header, how it reads a row for sorting, and the cell text (short enough for
// the table to fit a 1280 px window; a preview session's platform reads "pilot"; the full
// public id is the row's tooltip).
const COLUMNS = [
  { key: "started_at", head: "started", text: (r) => when(r.started_at) },
  { key: "public_id", head: "public id", text: (r) => r.public_id.slice(0, 8) },
  { key: "platform", head: "platform", text: (r) => r.platform },
  { key: "status", head: "status", text: (r) => STATUS_TEXT[r.status] ?? r.status },
  { key: "outcome", head: "outcome", text: (r) => (r.outcome ?? "–").replace(/_/g, " ") },
  { key: "last_seen", head: "last seen", text: (r) => when(r.last_seen) },
  { key: "world_order", head: "world order", text: (r) => r.world_order.replace(",", " → ") },
  { key: "attention", head: "attention checks failed", sort: (r) => r.attention.failed, text: (r) => attentionText(r.attention) },
  { key: "duration_s", head: "duration", text: (r) => duration(r.duration_s) },
  { key: "progress", head: "trials", sort: (r) => r.progress.done, text: (r) => `${r.progress.done} / ${r.progress.total}` },
  { key: "version", head: "study version", sort: (r) => r.config_current && r.bank_current,
    text: (r) => (r.config_current && r.bank_current ? "loaded" : [!r.config_current && "other config", !r.bank_current && "other bank"].filter(Boolean).join(", ")) },
];
const EXTERNAL_ID = { key: "external_id", head: "external id", text: (r) => r.external_id ?? "–" };

/** The sessions table; clicking a header sorts by it, `onPick(row)` opens a session's trials. */
export class ParticipantsTable {
  constructor(container, onPick) {
    this.container = container;
    this.onPick = onPick;
    this.sortKey = "started_at";
    this.ascending = true;
    this.rows = [];
    this.selected = null;
  }

  show(rows) {
    this.rows = rows;
    this.render();
  }

  sortBy(column) {
    this.ascending = this.sortKey === column.key ? !this.ascending : true;
    this.sortKey = column.key;
    this.render();
  }

  sorted(columns) {
    const column = columns.find((c) => c.key === this.sortKey) ?? columns[0];
    const value = column.sort ?? ((r) => r[column.key]);
    const sign = this.ascending ? 1 : -1;
    return [...this.rows].sort((a, b) => {
      const [x, y] = [value(a), value(b)];
      return x === y ? 0 : (x > y ? sign : -sign);
    });
  }

  render() {
    const columns = this.rows.some((r) => "external_id" in r) ? [...COLUMNS, EXTERNAL_ID] : COLUMNS;
    const table = el("table", { className: "summary sessions" });
    const head = table.createTHead().insertRow();
    head.append(el("th", { textContent: "#" }));
    for (const column of columns) {
      const arrow = column.key === this.sortKey ? (this.ascending ? " ▲" : " ▼") : "";
      const button = el("button", { type: "button", className: "sort", textContent: column.head + arrow });
      button.onclick = () => this.sortBy(column);
      const th = el("th", {}, button);
      th.setAttribute("aria-sort", arrow ? (this.ascending ? "ascending" : "descending") : "none");
      head.append(th);
    }
    head.append(el("th", { textContent: "replay" }));
    const body = table.createTBody();
    this.sorted(columns).forEach((row, i) => {
      const tr = body.insertRow();
      tr.dataset.publicId = row.public_id;
      tr.title = `session ${row.public_id}`;
      tr.classList.toggle("selected", row.public_id === this.selected);
      tr.classList.toggle("muted", row.pilot || row.status === "replaced");
      tr.insertCell().textContent = String(i + 1);
      for (const column of columns) tr.insertCell().textContent = column.text(row);
      const open = el("button", { type: "button", className: "secondary", textContent: "Trials" });
      open.onclick = () => {
        this.selected = row.public_id;
        this.render();
        this.onPick(row);
      };
      tr.insertCell().append(open);
    });
    if (!this.rows.length) this.container.replaceChildren(el("p", { textContent: "No sessions yet." }));
    else this.container.replaceChildren(table);
  }
}

/** The study-version warning (sessions per config and bank hash), or a quiet line. */
export function renderVersions(container, versions) {
  const parts = [];
  for (const warning of versions.warnings) parts.push(el("p", { className: "warning", textContent: warning }));
  const list = el("ul", { className: "hashes" });
  for (const what of ["config", "bank"]) {
    for (const entry of versions[what].sessions) {
      const sha = entry.sha256 ? entry.sha256.slice(0, 12) : "not recorded";
      list.append(el("li", { textContent: `${what} ${sha}: ${entry.sessions} sessions${entry.loaded ? " (loaded now)" : ""}` }));
    }
  }
  if (!versions.warnings.length) {
    parts.push(el("p", { className: "note", textContent: `Every session ran under the config and bank this server has loaded (tomstudy ${versions.app_version}).` }));
  }
  container.replaceChildren(...parts, list);
}

/** A round tick step (1, 2, 2.5 or 5 x 10^k) so that `ticks` steps reach `value`. */
function tickStep(value, ticks) {
  const raw = value / ticks;
  const power = 10 ** Math.floor(Math.log10(raw));
  return [1, 2, 2.5, 5, 10].map((m) => m * power).find((step) => step >= raw);
}

/** One world's error plot of every predictor in `models`: participants as dots (paired
 * lines), mean and 95% CI in black. */
export function errorPlot(world, entry, models) {
  const crowded = models.length > 5; // seven labels do not fit side by side in 440 px: tilt them
  const [w, h, left, top, bottom] = [440, crowded ? 320 : 280, 56, 44, crowded ? 76 : 36];
  const plot = svg("svg", { viewBox: `0 0 ${w} ${h}`, role: "img", class: "error-plot", "data-world": world });
  const highs = models.flatMap((m) => [...entry.models[m].participants, entry.models[m].ci95[1] ?? 0]);
  const yStep = tickStep(Math.max(...highs, 0.01), 4);
  const yMax = 4 * yStep;
  const y = (v) => top + (h - top - bottom) * (1 - v / yMax);
  const x = (i) => left + 30 + i * ((w - left - 40) / models.length);
  const test = entry.ours_vs_vae;
  plot.append(svg("title", {}, `${world}: alignment error per model, n = ${entry.n}`));
  plot.append(svg("text", { x: w / 2, y: 16, "text-anchor": "middle", class: "plot-title" }, `${world} (n = ${entry.n})`));
  plot.append(svg("text", { x: w / 2, y: 32, "text-anchor": "middle", class: "plot-sub" },
    `Ours − VAE ${num(test.mean_diff)} [${num(test.ci95_low)}, ${num(test.ci95_high)}], t = ${num(test.t, 2)}, p = ${test.p_two_sided === null ? "–" : test.p_two_sided.toPrecision(2)}`));
  for (let k = 0; k <= 4; k += 1) {
    const v = (yMax * k) / 4;
    plot.append(svg("line", { x1: left, x2: w - 8, y1: y(v), y2: y(v), class: "grid" }));
    plot.append(svg("text", { x: left - 6, y: y(v) + 4, "text-anchor": "end", class: "tick" }, String(Number(v.toPrecision(3)))));
  }
  const n = entry.models.ours.participants.length;
  const jitter = (p) => ((p * 7919) % 17) / 17 * 0.3 - 0.15; // fixed per participant: stable between refreshes
  const step = (w - left - 40) / models.length;
  for (let p = 0; p < n; p += 1) {
    const points = models.map((m, i) => `${x(i) + jitter(p) * step},${y(entry.models[m].participants[p])}`);
    plot.append(svg("polyline", { points: points.join(" "), class: "pair" }));
  }
  models.forEach((model, i) => {
    const { mean, ci95, participants } = entry.models[model];
    participants.forEach((v, p) => plot.append(svg("circle", { cx: x(i) + jitter(p) * step, cy: y(v), r: 3, fill: MODEL_COLORS[model], class: "dot" })));
    const cx = x(i) + 0.3 * step;
    if (ci95[0] !== null) {
      plot.append(svg("line", { x1: cx, x2: cx, y1: y(ci95[0]), y2: y(ci95[1]), class: "ci" }));
      for (const v of ci95) plot.append(svg("line", { x1: cx - 5, x2: cx + 5, y1: y(v), y2: y(v), class: "ci" }));
    }
    const meanDot = svg("circle", { cx, cy: y(mean), r: 4.5, class: "mean" });
    meanDot.append(svg("title", {}, `${MODEL_LABELS[model]}: ${num(mean)} [${num(ci95[0])}, ${num(ci95[1])}]`));
    plot.append(meanDot);
    const [lx, ly] = [x(i) + 0.1 * step, crowded ? h - bottom + 16 : h - 14];
    plot.append(svg("text", crowded
      ? { x: lx, y: ly, "text-anchor": "end", transform: `rotate(-35 ${lx} ${ly})`, class: "tick" }
      : { x: lx, y: ly, "text-anchor": "middle", class: "tick" }, MODEL_LABELS[model]));
  });
  return plot;
}

/** Per world, the pre-registered primary test's verdict in words: the report's first-page
 * sentence (analysis/verdicts.py primary_sentence), computed by the server. */
export function renderVerdicts(container, verdicts) {
  const worlds = Object.entries(verdicts ?? {});
  if (!worlds.length) {
    container.replaceChildren(el("li", { textContent: "Not yet: the test needs kept participants whose answers ran the loaded trial bank." }));
    return;
  }
  container.replaceChildren(...worlds.map(([world, sentence]) => {
    const item = el("li", { textContent: sentence });
    item.dataset.world = world;
    return item;
  }));
}

/** Per world: the error plot and a table of mean [95% CI] per predictor (`predictors`, in
 * order; `style` their colours and labels). */
export function renderErrors(container, worlds, predictors, style) {
  useStyle(style);
  const names = Object.keys(worlds);
  if (!names.length) {
    container.replaceChildren(el("p", { textContent: "No participant is kept under these rules yet." }));
    return;
  }
  const rows = names.map((world) => {
    const tr = el("tr");
    tr.append(el("td", { textContent: world }), el("td", { textContent: String(worlds[world].n) }));
    for (const m of predictors) {
      const { mean, ci95 } = worlds[world].models[m];
      tr.append(el("td", { textContent: `${num(mean)} [${num(ci95[0])}, ${num(ci95[1])}]` }));
    }
    return tr;
  });
  const head = el("tr", {}, ...["world", "n", ...predictors.map((m) => MODEL_LABELS[m])].map((t) => el("th", { textContent: t })));
  const table = el("table", { className: "summary ci-table" }, el("thead", {}, head), el("tbody", {}, ...rows));
  container.replaceChildren(el("div", { className: "plot-row" }, ...names.map((w) => errorPlot(w, worlds[w], predictors))), table);
}

function arrow(ctx, view, from, dir, lengthM, color, width) {
  const [x0, y0] = view.toPx(from);
  const [x1, y1] = view.toPx([from[0] + dir[0] * lengthM, from[1] + dir[1] * lengthM]);
  const angle = Math.atan2(y1 - y0, x1 - x0);
  const head = Math.max(5, width * 3);
  ctx.strokeStyle = color;
  ctx.fillStyle = color;
  ctx.lineWidth = width;
  ctx.beginPath();
  ctx.moveTo(x0, y0);
  ctx.lineTo(x1, y1);
  ctx.stroke();
  ctx.beginPath();
  ctx.moveTo(x1, y1);
  ctx.lineTo(x1 - head * Math.cos(angle - 0.4), y1 - head * Math.sin(angle - 0.4));
  ctx.lineTo(x1 - head * Math.cos(angle + 0.4), y1 - head * Math.sin(angle + 0.4));
  ctx.closePath();
  ctx.fill();
}

/** A world's scene cut to the stretch of road where its start states lie (as the report does). */
function croppedScene(field) {
  const { scene, arrow_m: arrowM, x_range_m: [low, high] } = field;
  if (!scene.lanes?.length) return scene;
  const bounds = { ...scene.bounds, x_min_m: Math.max(scene.bounds.x_min_m, low - 2 * arrowM), x_max_m: Math.min(scene.bounds.x_max_m, high + 2 * arrowM) };
  return { ...scene, bounds };
}

/** One field panel on a canvas: participants' (black) and the model's arrows per start state. */
export function drawField(canvas, field, panel) {
  const scene = croppedScene(field);
  const { ctx, view } = prepareCanvas(canvas, scene);
  drawBackground(ctx, view, scene);
  for (const state of panel.states) {
    arrow(ctx, view, state.at, state.human, field.arrow_m, MODEL_COLORS.human, 2.2);
    arrow(ctx, view, state.at, state.model, field.arrow_m, MODEL_COLORS[panel.model], 1.6);
  }
}

/** Per world, each model's most common codes: a canvas per panel, drawn from the JSON. */
export function renderFields(container, fields) {
  const blocks = Object.entries(fields).map(([world, field]) => {
    const wide = Boolean(field.scene.lanes?.length);
    const grid = el("div", { className: wide ? "field-grid wide" : "field-grid" });
    const block = el("div", { className: "field-world" }, el("h4", { textContent: world }), grid);
    const canvases = field.panels.map((panel) => {
      const canvas = el("canvas", { className: "field-canvas" });
      canvas.setAttribute("aria-label", `${world}: ${MODEL_LABELS[panel.model]} code ${panel.code}`);
      const caption = `${MODEL_LABELS[panel.model]} code ${panel.code}: ${panel.trials} trials, error ${num(panel.error, 2)}`;
      grid.append(el("figure", { className: "field-panel" }, canvas, el("figcaption", { textContent: caption })));
      return [canvas, panel];
    });
    return [block, field, canvases];
  });
  container.replaceChildren(...blocks.map(([block]) => block));
  if (!blocks.length) container.append(el("p", { textContent: "No answers to draw yet." }));
  for (const [, field, canvases] of blocks) canvases.forEach(([canvas, panel]) => drawField(canvas, field, panel));
}
