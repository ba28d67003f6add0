// Draw a world from its scene JSON (app/data/scene.py) on a canvas.
// Scene metres map to CSS pixels with one uniform scale; y grows downward in both.
import { WORDS } from "./words.js";

// The colours are the server's (app/data/scene.py BROWSER_PALETTE, where their contrast
// rule is explained), which every page that draws a scene carries as #scene-palette.
const PALETTE = JSON.parse(document.getElementById("scene-palette").textContent);
export const ROBOT_COLOR = PALETTE.robot;
export const HUMAN_COLOR = PALETTE.human;
const HUMAN_TEXT = PALETTE.human_text;
export const GROUND = PALETTE.ground;
const LANE_MARK = PALETTE.lane_mark;
export const GOAL_COLORS = PALETTE.goals;
export const MAP = PALETTE.map;
const MARGIN_PX = 24;

/** Uniform metres->CSS-pixel transform that fits `bounds` in a w x h box with margins. */
export function fitView(bounds, cssWidth, cssHeight, margin = MARGIN_PX) {
  const spanX = bounds.x_max_m - bounds.x_min_m;
  const spanY = bounds.y_max_m - bounds.y_min_m;
  // a box not laid out yet (hidden panel, zero width) must not give a negative scale: canvas
  // calls reject negative radii, and the next resize redraws at the real size
  const scale = Math.max(1e-3, Math.min((cssWidth - 2 * margin) / spanX, (cssHeight - 2 * margin) / spanY));
  const centre = [(bounds.x_min_m + bounds.x_max_m) / 2, (bounds.y_min_m + bounds.y_max_m) / 2];
  return viewAt(scale, centre, cssWidth, cssHeight);
}

/** The transform that draws `scale` px per metre with scene point `centre` in the box's middle. */
export function viewAt(scale, centre, cssWidth, cssHeight) {
  const offsetX = cssWidth / 2 - centre[0] * scale;
  const offsetY = cssHeight / 2 - centre[1] * scale;
  return {
    scale,
    width: cssWidth,
    height: cssHeight,
    toPx: ([x, y]) => [offsetX + x * scale, offsetY + y * scale],
    toM: ([px, py]) => [(px - offsetX) / scale, (py - offsetY) / scale],
    offsetX,
    offsetY,
  };
}

/**
 * The view centre along one axis: the scene's middle when its span fits the box, else
 * `want` moved as little as needed to keep `keep` = [lo, hi] (metres) inside the box and
 * the view inside the scene.
 */
export function centreOnAxis(lo, hi, spanPx, scale, want, keep, margin = MARGIN_PX) {
  const half = (spanPx / 2 - margin) / scale;
  if (hi - lo <= 2 * half) return (lo + hi) / 2;
  let centre = Math.min(Math.max(want, keep[1] - half), keep[0] + half);
  centre = Math.min(Math.max(centre, lo + half), hi - half);
  return centre;
}

// Vertical room the page needs besides the canvas (header, heading, controls, legend).
const PAGE_CHROME_PX = 250;

/** CSS height that shows the scene large enough to click on, for a given width. */
export function preferredHeight(bounds, cssWidth, {
  minPx = 160, maxPx = Math.max(320, window.innerHeight - PAGE_CHROME_PX),
} = {}) {
  const aspect = (bounds.y_max_m - bounds.y_min_m) / (bounds.x_max_m - bounds.x_min_m);
  return Math.round(Math.max(minPx, Math.min(maxPx, (cssWidth - 2 * MARGIN_PX) * aspect + 2 * MARGIN_PX)));
}

/**
 * Size the canvas backing store for devicePixelRatio and return {ctx, view}: the whole scene,
 * fitted. The view is also written to data-* attributes so tests and tools can map metres to
 * pixels.
 */
export function prepareCanvas(canvas, scene) {
  const cssWidth = canvas.parentElement.clientWidth;
  const cssHeight = preferredHeight(scene.bounds, cssWidth);
  const ctx = sizeCanvas(canvas, cssWidth, cssHeight);
  const view = fitView(scene.bounds, cssWidth, cssHeight);
  publishView(canvas, view);
  return { ctx, view, cssWidth, cssHeight };
}

/** Give the canvas a CSS size and a backing store for devicePixelRatio; its 2-D context. */
export function sizeCanvas(canvas, cssWidth, cssHeight) {
  const dpr = window.devicePixelRatio || 1;
  canvas.style.width = `${cssWidth}px`;
  canvas.style.height = `${cssHeight}px`;
  canvas.width = Math.round(cssWidth * dpr);
  canvas.height = Math.round(cssHeight * dpr);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  return ctx;
}

/** Write the view's scale and origin to the canvas' data-* attributes. */
export function publishView(canvas, view) {
  Object.assign(canvas.dataset, {
    pxPerM: view.scale.toFixed(6),
    originXPx: view.toPx([0, 0])[0].toFixed(3),
    originYPx: view.toPx([0, 0])[1].toFixed(3),
  });
}

/**
 * Background: bounds, road and lanes (or a recorded scene's map), obstacles and goals. `t` is
 * the clip's fractional step: in a moving frame the lane markings slide backwards by the
 * distance it has moved.
 */
export function drawBackground(ctx, view, scene, t = 0, { labels = true } = {}) {
  const { bounds } = scene;
  const [x0, y0] = view.toPx([bounds.x_min_m, bounds.y_min_m]);
  const [x1, y1] = view.toPx([bounds.x_max_m, bounds.y_max_m]);
  ctx.clearRect(0, 0, ctx.canvas.width, ctx.canvas.height);
  ctx.fillStyle = scene.recorded ? MAP.field : scene.lanes?.length ? GROUND.shoulder : GROUND.field;
  ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
  if (scene.recorded) {
    ctx.save();
    clipToScene(ctx, view, bounds);
    drawDriven(ctx, view, scene.recorded.driven);
    drawMapLines(ctx, view, scene.recorded);
    ctx.restore();
  }
  drawLanes(ctx, view, scene, t);
  (scene.obstacles || []).forEach((obstacle) => drawObstacle(ctx, view, obstacle));
  (scene.goals || []).forEach((goal, k) => drawGoal(ctx, view, goal, k, labels));
  ctx.strokeStyle = "#6b6b6b";
  ctx.lineWidth = 1;
  ctx.setLineDash([]);
  ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
}

/** Clip what is drawn next to the scene's bounds (the caller saves and restores). */
export function clipToScene(ctx, view, bounds) {
  const [x0, y0] = view.toPx([bounds.x_min_m, bounds.y_min_m]);
  const [x1, y1] = view.toPx([bounds.x_max_m, bounds.y_max_m]);
  ctx.beginPath();
  ctx.rect(x0, y0, x1 - x0, y1 - y0);
  ctx.clip();
}

// Highway lane markings: 3 m painted, 9 m gap (the US MUTCD broken line), drawn in metres so
// their scroll speed on screen is the frame's speed.
const DASH_M = [3, 9];

function drawLanes(ctx, view, scene, t) {
  const { bounds, lanes = [] } = scene;
  if (!lanes.length) return;
  const sorted = [...lanes].sort((a, b) => a.y_center_m - b.y_center_m);
  for (const lane of sorted) {
    const [lx, top] = view.toPx([bounds.x_min_m, lane.y_center_m - lane.width_m / 2]);
    const [rx, bottom] = view.toPx([bounds.x_max_m, lane.y_center_m + lane.width_m / 2]);
    ctx.fillStyle = GROUND.road;
    ctx.fillRect(lx, top, rx - lx, bottom - top);
  }
  ctx.strokeStyle = LANE_MARK;
  ctx.lineWidth = 1.5;
  sorted.forEach((lane, i) => {
    const edges = [lane.y_center_m - lane.width_m / 2, lane.y_center_m + lane.width_m / 2];
    edges.forEach((edgeY, side) => {
      const outer = (i === 0 && side === 0) || (i === sorted.length - 1 && side === 1);
      if (!outer && side === 0) return; // shared edge: drawn once, dashed
      ctx.setLineDash(outer ? [] : DASH_M.map((m) => m * view.scale));
      ctx.lineDashOffset = (scene.frame_speed_mps || 0) * scene.dt_s * t * view.scale;
      const [ax, ay] = view.toPx([bounds.x_min_m, edgeY]);
      const [bx] = view.toPx([bounds.x_max_m, edgeY]);
      ctx.beginPath();
      ctx.moveTo(ax, ay);
      ctx.lineTo(bx, ay);
      ctx.stroke();
    });
  });
  ctx.setLineDash([]);
  ctx.lineDashOffset = 0;
}

const drivenBoxes = new WeakMap();

/** The driven area as rectangles [x0, y0, x1, y1] (m): a row's run that repeats the run
 * just above it extends that rectangle down, so a straight band is one rectangle. */
function mergedRuns(driven) {
  if (drivenBoxes.has(driven)) return drivenBoxes.get(driven);
  const { cell_m: cell, x0_m: left, y0_m: top } = driven;
  const open = new Map(); // "first,last" -> the rectangle that run reached, and its last row
  const boxes = [];
  for (const [row, first, last] of driven.runs) {
    const key = `${first},${last}`;
    const above = open.get(key);
    if (above?.row === row - 1) {
      above.row = row;
      above.box[3] = top + (row + 1) * cell;
      continue;
    }
    const box = [left + first * cell, top + row * cell, left + (last + 1) * cell, top + (row + 1) * cell];
    boxes.push(box);
    open.set(key, { row, box });
  }
  drivenBoxes.set(driven, boxes);
  return boxes;
}

/** Where recorded cars drove, in the road colour: one path, filled once, so rectangles that
 * touch leave no anti-aliased seam between them. */
function drawDriven(ctx, view, driven) {
  if (!driven) return;
  ctx.beginPath();
  for (const [ax, ay, bx, by] of mergedRuns(driven)) {
    const [x0, y0] = view.toPx([ax, ay]);
    const [x1, y1] = view.toPx([bx, by]);
    ctx.rect(x0, y0, x1 - x0, y1 - y0);
  }
  ctx.fillStyle = MAP.road;
  ctx.fill();
}

// How a map's lines are drawn, faintest first: width in metres, held within [min, max] CSS px
// so a line stays visible on the small overview map and does not swamp the close-up. A kind
// not listed is not drawn: `virtual` lanelet borders (no paint), which banks built before
// app/recordings/scene.py left them out still carry.
const MAP_LINES = [
  ["border", { widthM: 0.12, minPx: 1, maxPx: 2 }],
  ["kerb", { widthM: 0.3, minPx: 1.5, maxPx: 4 }],
  ["stop", { widthM: 0.5, minPx: 2, maxPx: 6 }],
];

const linesByKind = new WeakMap();

/** A recorded scene's map lines by kind, in MAP_LINES' kinds and the scene's order; a
 * scene's lines never change, so each scene's are grouped once, not on every frame. */
function mapLinesByKind(recorded) {
  if (linesByKind.has(recorded)) return linesByKind.get(recorded);
  const groups = new Map(MAP_LINES.map(([kind]) => [kind, []]));
  for (const line of recorded.lines || []) groups.get(line.kind)?.push(line);
  linesByKind.set(recorded, groups);
  return groups;
}

function drawMapLines(ctx, view, recorded) {
  const groups = mapLinesByKind(recorded);
  for (const [kind, style] of MAP_LINES) {
    ctx.strokeStyle = MAP[kind];
    ctx.lineWidth = Math.min(style.maxPx, Math.max(style.minPx, style.widthM * view.scale));
    ctx.lineJoin = "round";
    for (const line of groups.get(kind)) {
      ctx.setLineDash(line.dashed ? DASH_M.map((m) => m * view.scale) : []);
      ctx.beginPath();
      line.points.forEach((p, i) => {
        const [px, py] = view.toPx(p);
        if (i === 0) ctx.moveTo(px, py);
        else ctx.lineTo(px, py);
      });
      ctx.stroke();
    }
  }
  ctx.setLineDash([]);
}

function drawObstacle(ctx, view, obstacle) {
  const [cx, cy] = view.toPx([obstacle.x_m, obstacle.y_m]);
  ctx.fillStyle = "#555555";
  ctx.beginPath();
  ctx.arc(cx, cy, obstacle.radius_m * view.scale, 0, 2 * Math.PI);
  ctx.fill();
}

function drawGoal(ctx, view, goal, k, withLabel) {
  const [cx, cy] = view.toPx([goal.x_m, goal.y_m]);
  ctx.strokeStyle = GOAL_COLORS[k % GOAL_COLORS.length];
  ctx.lineWidth = Math.min(3, Math.max(1.5, view.scale * 0.04));
  ctx.setLineDash([6, 4]);
  ctx.beginPath();
  ctx.arc(cx, cy, goal.radius_m * view.scale, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.setLineDash([]);
  if (withLabel) label(ctx, goal.label || `goal ${k + 1}`, cx, cy, "#222222", 12);
}

/** A text on a white box centred at (x, y); returns the box {x0, y0, x1, y1} in CSS px. */
export function label(ctx, text, x, y, color, sizePx, background = "rgba(255,255,255,0.92)") {
  const box = labelBox(ctx, text, x, y, sizePx);
  ctx.fillStyle = background;
  ctx.fillRect(box.x0, box.y0, box.x1 - box.x0, box.y1 - box.y0);
  ctx.fillStyle = color;
  ctx.fillText(text, x, y);
  return box;
}

function labelBox(ctx, text, x, y, sizePx) {
  ctx.font = `bold ${sizePx}px system-ui, sans-serif`;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  const half = (ctx.measureText(text).width + 6) / 2;
  return { x0: x - half, y0: y - sizePx / 2 - 2, x1: x + half, y1: y + sizePx / 2 + 2 };
}

function overlaps(a, b) {
  return a.x0 < b.x1 && b.x0 < a.x1 && a.y0 < b.y1 && b.y0 < a.y1;
}

/** A box around a point, `r` px each way. */
export function boxAround([x, y], r) {
  return { x0: x - r, y0: y - r, x1: x + r, y1: y + r };
}

/**
 * Labels that never cover what is drawn: `block` the boxes of agents and markers, then
 * `place` each label at the first of its candidate spots that overlaps nothing blocked or
 * placed and stays on the canvas. `boxes` keeps every placed label (tests read them).
 */
export class LabelLayout {
  constructor(ctx, width, height) {
    this.ctx = ctx;
    this.width = width;
    this.height = height;
    this.blocked = [];
    this.boxes = [];
  }

  block(box) {
    this.blocked.push(box);
  }

  /**
   * Draw `text` at the first free spot around `anchor` (at `distance` px, `angles` first;
   * further out when nothing near is free, e.g. a click on the robot's own body, with a thin
   * line back to the anchor).
   */
  place(text, anchor, distance, { angles = [], ...style } = {}) {
    const box = this.placeFirst(text, ringSpots(anchor, distance, angles), style);
    const [cx, cy] = [(box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2];
    if (Math.hypot(cx - anchor[0], cy - anchor[1]) > 2 * distance) this.leader(anchor, box);
    return box;
  }

  /** Draw `text` at the first of `spots` where it covers nothing and stays on the canvas. */
  placeFirst(text, spots, { color = "#111111", sizePx = 12 } = {}) {
    const fits = (box) => box.x0 >= 0 && box.y0 >= 0 && box.x1 <= this.width && box.y1 <= this.height
      && ![...this.blocked, ...this.boxes].some((other) => overlaps(box, other));
    const spot = spots.find(([x, y]) => fits(labelBox(this.ctx, text, x, y, sizePx))) ?? spots[0];
    const box = label(this.ctx, text, spot[0], spot[1], color, sizePx);
    this.boxes.push({ ...box, text });
    return box;
  }

  /** A thin line from `anchor` to the nearest point of `box`. */
  leader([ax, ay], box) {
    const x = Math.min(Math.max(ax, box.x0), box.x1);
    const y = Math.min(Math.max(ay, box.y0), box.y1);
    this.ctx.save();
    this.ctx.strokeStyle = "#111111";
    this.ctx.lineWidth = 1;
    this.ctx.setLineDash([]);
    this.ctx.beginPath();
    this.ctx.moveTo(ax, ay);
    this.ctx.lineTo(x, y);
    this.ctx.stroke();
    this.ctx.restore();
  }
}

/** Spots on rings around `anchor` (1 to 8 x `distance`): `angles` first, then above, below,
 * beside, the diagonals and the angles between. */
function ringSpots(anchor, distance, angles) {
  const order = [-4, 4, 0, 8, -2, -6, 2, 6, -3, -5, 3, 5, -1, -7, 1, 7].map((k) => (k * Math.PI) / 8);
  return [1, 1.6, 2.4, 3.5, 5, 6.5, 8].flatMap((f) => [...angles, ...order].map((a) => (
    [anchor[0] + f * distance * Math.cos(a), anchor[1] + f * distance * Math.sin(a)])));
}

/**
 * Role of agent i: 0 is the robot, 1 the human (DESIGN.md section 3); its tag is
 * the study's key for it (app/study/words.py). `sizes`, a clip's
 * [length, width] (m) per agent as recorded (app/study/trials.py Clip), replace the scene's.
 */
export function agentStyle(scene, i, sizes = null) {
  const shape = scene.agents?.[i] || { kind: "disc", length_m: 1, width_m: 1 };
  const size = sizes?.[i];
  const isRobot = i === 0;
  return {
    ...shape,
    ...(size ? { length_m: size[0], width_m: size[1] } : {}),
    color: isRobot ? ROBOT_COLOR : HUMAN_COLOR,
    tag: isRobot ? WORDS.agent_key : WORDS.other_key,
    name: isRobot ? "robot" : "human",
    hatched: !isRobot,
  };
}

const stripeTiles = new Map();

function stripes(ctx, color) {
  if (!stripeTiles.has(color)) stripeTiles.set(color, stripeTile(color));
  return ctx.createPattern(stripeTiles.get(color), "repeat");
}

function stripeTile(color) {
  const tile = document.createElement("canvas");
  tile.width = 8;
  tile.height = 8;
  const t = tile.getContext("2d");
  t.fillStyle = color;
  t.fillRect(0, 0, 8, 8);
  t.strokeStyle = "rgba(0,0,0,0.55)";
  t.lineWidth = 2;
  t.beginPath();
  t.moveTo(0, 8);
  t.lineTo(8, 0);
  t.stroke();
  return tile;
}

/**
 * Draw one agent at `position` with `heading` (radians, scene frame); returns its box.
 * Robot: solid fill and "R"; human: striped fill and "H"; cars carry a nose wedge. With
 * `seeThrough` the body is a light tint inside a thick outline of its colour, so clicks and
 * the reach disc under it stay visible (the robot's start in the prediction view).
 */
export function drawAgent(ctx, view, style, position, heading, { alpha = 1, tag = true, seeThrough = false } = {}) {
  const [cx, cy] = view.toPx(position);
  const length = Math.max(style.length_m * view.scale, 10);
  const width = Math.max(style.width_m * view.scale, 10);
  const car = style.kind === "car";
  ctx.save();
  ctx.translate(cx, cy);
  ctx.rotate(heading || 0);
  const body = () => {
    ctx.beginPath();
    if (car) ctx.rect(-length / 2, -width / 2, length, width);
    else ctx.arc(0, 0, length / 2, 0, 2 * Math.PI);
  };
  ctx.globalAlpha = alpha * (seeThrough ? 0.25 : 1);
  ctx.fillStyle = style.hatched ? stripes(ctx, style.color) : style.color;
  body();
  ctx.fill();
  ctx.globalAlpha = alpha;
  ctx.strokeStyle = seeThrough ? style.color : "#111111";
  ctx.lineWidth = seeThrough ? 3 : 1.5;
  body();
  ctx.stroke();
  ctx.fillStyle = "#111111";
  ctx.strokeStyle = "#111111";
  if (car) { // nose wedge shows the heading
    const back = length / 2 - Math.min(width, length / 3);
    ctx.beginPath();
    ctx.moveTo(length / 2, 0);
    ctx.lineTo(back, -width / 2);
    ctx.lineTo(back, width / 2);
    ctx.closePath();
    if (seeThrough) ctx.stroke();
    else ctx.fill();
  } else if (heading !== undefined && heading !== null) {
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(0, 0);
    ctx.lineTo(length / 2, 0);
    ctx.stroke();
  }
  ctx.restore();
  if (tag) {
    ctx.save();
    ctx.globalAlpha = alpha;
    label(ctx, style.tag, cx, cy - Math.max(width, length) / 2 - 10, tagColor(style), 12);
    ctx.restore();
  }
  return agentBox(view, style, position, heading);
}

/** The text colour of an agent's tag (dark enough on a white label). */
export function tagColor(style) {
  return style.name === "human" ? HUMAN_TEXT : style.color;
}

/** The axis-aligned box an agent covers on screen, turned to `heading` (outline included). */
export function agentBox(view, style, position, heading) {
  const half = [Math.max(style.length_m * view.scale, 10) / 2, Math.max(style.width_m * view.scale, 10) / 2];
  const [c, s] = [Math.abs(Math.cos(heading || 0)), Math.abs(Math.sin(heading || 0))];
  const [x, y] = view.toPx(position);
  const [rx, ry] = [half[0] * c + half[1] * s + 1.5, half[0] * s + half[1] * c + 1.5];
  return { x0: x - rx, y0: y - ry, x1: x + rx, y1: y + ry };
}

/** Draw every agent (shapes first), then each tag where it covers no agent nor other tag. */
export function drawAgents(ctx, view, agents, layout) {
  const boxes = agents.map(({ style, position, heading, alpha }) => {
    const box = drawAgent(ctx, view, style, position, heading, { alpha, tag: false });
    layout.block(box);
    return box;
  });
  agents.forEach(({ style }, i) => placeTag(layout, style, boxes[i]));
  return boxes;
}

/** An agent's tag ("R", "H") just off an edge of its box, where it covers no agent nor other
 * label (above, below, right, left, the corners; then further out). */
export function placeTag(layout, style, box) {
  const [cx, cy] = [(box.x0 + box.x1) / 2, (box.y0 + box.y1) / 2];
  const m = 11;
  const edges = [[cx, box.y0 - m], [cx, box.y1 + m], [box.x1 + m, cy], [box.x0 - m, cy],
    [box.x1 + m, box.y0 - m], [box.x0 - m, box.y0 - m], [box.x1 + m, box.y1 + m], [box.x0 - m, box.y1 + m]];
  const further = ringSpots([cx, cy], Math.max(box.x1 - box.x0, box.y1 - box.y0) / 2 + 2 * m, []);
  return layout.placeFirst(style.tag, [...edges, ...further], { color: tagColor(style) });
}

/**
 * A polyline through scene points, in the agent's colour (dashed for the human, dotted for
 * a past stretch with `past`). Drawn opaque: a faded trace loses its contrast.
 */
export function drawTrace(ctx, view, style, points, { alpha = 1, dots = false, width = 2.5, past = false } = {}) {
  if (points.length < 2) return;
  ctx.save();
  ctx.globalAlpha = alpha;
  ctx.strokeStyle = style.color;
  ctx.lineWidth = width;
  ctx.lineCap = past ? "round" : "butt";
  ctx.setLineDash(style.hatched ? [6, 4] : past ? [0.1, 6] : []);
  ctx.beginPath();
  points.forEach((p, i) => {
    const [px, py] = view.toPx(p);
    if (i === 0) ctx.moveTo(px, py);
    else ctx.lineTo(px, py);
  });
  ctx.stroke();
  ctx.setLineDash([]);
  if (dots) {
    ctx.fillStyle = style.color;
    for (const p of points) {
      const [px, py] = view.toPx(p);
      ctx.beginPath();
      ctx.arc(px, py, 2.5, 0, 2 * Math.PI);
      ctx.fill();
    }
  }
  ctx.restore();
}

/** A numbered white disc on a clicked position (the participant's input and the replay). */
export function drawClickMarker(ctx, view, point, label, { stroke = "#000000", radius = 8 } = {}) {
  const [px, py] = view.toPx(point);
  ctx.save();
  ctx.fillStyle = "#ffffff";
  ctx.strokeStyle = stroke;
  ctx.lineWidth = radius > 8 ? 2.5 : 2;
  ctx.beginPath();
  ctx.arc(px, py, radius, 0, 2 * Math.PI);
  ctx.fill();
  ctx.stroke();
  ctx.fillStyle = "#111111";
  ctx.font = `bold ${radius + 2}px system-ui, sans-serif`;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  ctx.fillText(label, px, py + 0.5);
  ctx.restore();
}

/** A hollow ring on a clicked position: it covers nothing under it; returns its box. */
export function drawRing(ctx, view, point, { color = ROBOT_COLOR, radius = 7 } = {}) {
  const [px, py] = view.toPx(point);
  ctx.save();
  ctx.setLineDash([]);
  for (const [stroke, width] of [["#ffffff", 5], [color, 2.5]]) {
    ctx.strokeStyle = stroke;
    ctx.lineWidth = width;
    ctx.beginPath();
    ctx.arc(px, py, radius, 0, 2 * Math.PI);
    ctx.stroke();
  }
  ctx.fillStyle = color;
  ctx.beginPath();
  ctx.arc(px, py, 1.5, 0, 2 * Math.PI);
  ctx.fill();
  ctx.restore();
  return boxAround([px, py], radius + 2.5);
}

/**
 * For a scene point outside the view: an arrow at the canvas edge pointing to it, with its
 * name, so the person knows where the agent or goal is. Returns the label box, or null when
 * the point is in view.
 */
export function drawPointer(ctx, view, point, text, color, layout) {
  const [px, py] = view.toPx(point);
  const inset = 16;
  if (px >= 0 && px <= view.width && py >= 0 && py <= view.height) return null;
  const cx = view.width / 2;
  const cy = view.height / 2;
  const angle = Math.atan2(py - cy, px - cx);
  const reach = Math.min((view.width / 2 - inset) / Math.abs(Math.cos(angle) || 1e-9),
    (view.height / 2 - inset) / Math.abs(Math.sin(angle) || 1e-9));
  const tip = [cx + reach * Math.cos(angle), cy + reach * Math.sin(angle)];
  ctx.save();
  ctx.fillStyle = color;
  ctx.translate(tip[0], tip[1]);
  ctx.rotate(angle);
  ctx.beginPath();
  ctx.moveTo(8, 0);
  ctx.lineTo(-6, -7);
  ctx.lineTo(-6, 7);
  ctx.closePath();
  ctx.fill();
  ctx.restore();
  return layout.place(text, tip, 18, { color: "#111111", sizePx: 11, angles: [angle + Math.PI] });
}
