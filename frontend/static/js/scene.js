// Draw a world from its scene JSON (app/data/scene.py) on a canvas.
// Scene metres map to CSS pixels with one uniform scale; y grows downward in both.

export const ROBOT_COLOR = "#0072B2";
export const HUMAN_COLOR = "#E69F00";
// Okabe-Ito, as in analysis/scene_plot.py LABEL_COLORS.
export const LABEL_COLORS = ["#009E73", "#D55E00", "#CC79A7", "#56B4E9", "#F0E442", "#000000"];
const MARGIN_PX = 24;

/** Uniform metres->CSS-pixel transform that fits `bounds` in a w x h box with margins. */
export function fitView(bounds, cssWidth, cssHeight, margin = MARGIN_PX) {
  const spanX = bounds.x_max_m - bounds.x_min_m;
  const spanY = bounds.y_max_m - bounds.y_min_m;
  // a box not laid out yet (hidden panel, zero width) must not give a negative scale: canvas
  // calls reject negative radii, and the next resize redraws at the real size
  const scale = Math.max(1e-3, Math.min((cssWidth - 2 * margin) / spanX, (cssHeight - 2 * margin) / spanY));
  const offsetX = (cssWidth - scale * spanX) / 2;
  const offsetY = (cssHeight - scale * spanY) / 2;
  return {
    scale,
    toPx: ([x, y]) => [offsetX + (x - bounds.x_min_m) * scale, offsetY + (y - bounds.y_min_m) * scale],
    toM: ([px, py]) => [bounds.x_min_m + (px - offsetX) / scale, bounds.y_min_m + (py - offsetY) / scale],
    offsetX,
    offsetY,
  };
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
 * Size the canvas backing store for devicePixelRatio and return {ctx, view}.
 * The view is also written to data-* attributes so tests and tools can map metres to pixels.
 */
export function prepareCanvas(canvas, scene) {
  const cssWidth = canvas.parentElement.clientWidth;
  const cssHeight = preferredHeight(scene.bounds, cssWidth);
  const dpr = window.devicePixelRatio || 1;
  canvas.style.width = `${cssWidth}px`;
  canvas.style.height = `${cssHeight}px`;
  canvas.width = Math.round(cssWidth * dpr);
  canvas.height = Math.round(cssHeight * dpr);
  const ctx = canvas.getContext("2d");
  ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  const view = fitView(scene.bounds, cssWidth, cssHeight);
  Object.assign(canvas.dataset, {
    pxPerM: view.scale.toFixed(6),
    originXPx: view.toPx([0, 0])[0].toFixed(3),
    originYPx: view.toPx([0, 0])[1].toFixed(3),
  });
  return { ctx, view, cssWidth, cssHeight };
}

/**
 * Background: bounds, road and lanes, obstacles and goals. `t` is the clip's fractional
 * step: in a moving frame the lane markings slide backwards by the distance it has moved.
 */
export function drawBackground(ctx, view, scene, t = 0) {
  const { bounds } = scene;
  const [x0, y0] = view.toPx([bounds.x_min_m, bounds.y_min_m]);
  const [x1, y1] = view.toPx([bounds.x_max_m, bounds.y_max_m]);
  ctx.clearRect(0, 0, ctx.canvas.width, ctx.canvas.height);
  ctx.fillStyle = scene.lanes?.length ? "#d9dde1" : "#fbfbf8";
  ctx.fillRect(x0, y0, x1 - x0, y1 - y0);
  drawLanes(ctx, view, scene, t);
  (scene.obstacles || []).forEach((obstacle) => drawObstacle(ctx, view, obstacle));
  (scene.goals || []).forEach((goal, k) => drawGoal(ctx, view, goal, k));
  ctx.strokeStyle = "#6b6b6b";
  ctx.lineWidth = 1;
  ctx.setLineDash([]);
  ctx.strokeRect(x0, y0, x1 - x0, y1 - y0);
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
    ctx.fillStyle = "#5f6368";
    ctx.fillRect(lx, top, rx - lx, bottom - top);
  }
  ctx.strokeStyle = "#ffffff";
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

function drawObstacle(ctx, view, obstacle) {
  const [cx, cy] = view.toPx([obstacle.x_m, obstacle.y_m]);
  ctx.fillStyle = "#555555";
  ctx.beginPath();
  ctx.arc(cx, cy, obstacle.radius_m * view.scale, 0, 2 * Math.PI);
  ctx.fill();
}

function drawGoal(ctx, view, goal, k) {
  const [cx, cy] = view.toPx([goal.x_m, goal.y_m]);
  const color = LABEL_COLORS[k % LABEL_COLORS.length];
  ctx.strokeStyle = color;
  ctx.lineWidth = 2.5;
  ctx.setLineDash([6, 4]);
  ctx.beginPath();
  ctx.arc(cx, cy, goal.radius_m * view.scale, 0, 2 * Math.PI);
  ctx.stroke();
  ctx.setLineDash([]);
  label(ctx, goal.label || `goal ${k + 1}`, cx, cy, "#222222", 12);
}

function label(ctx, text, x, y, color, sizePx, background = "rgba(255,255,255,0.85)") {
  ctx.font = `bold ${sizePx}px system-ui, sans-serif`;
  ctx.textAlign = "center";
  ctx.textBaseline = "middle";
  const width = ctx.measureText(text).width + 6;
  ctx.fillStyle = background;
  ctx.fillRect(x - width / 2, y - sizePx / 2 - 2, width, sizePx + 4);
  ctx.fillStyle = color;
  ctx.fillText(text, x, y);
}

/** Role of agent i: 0 is the robot, 1 the human (DESIGN.md section 3). */
export function agentStyle(scene, i) {
  const shape = scene.agents?.[i] || { kind: "disc", length_m: 1, width_m: 1 };
  const isRobot = i === 0;
  return {
    ...shape,
    color: isRobot ? ROBOT_COLOR : HUMAN_COLOR,
    tag: isRobot ? "R" : "H",
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
 * Draw one agent at `position` with `heading` (radians, scene frame).
 * Robot: solid fill and "R"; human: striped fill and "H"; cars carry a nose wedge.
 */
export function drawAgent(ctx, view, style, position, heading, { alpha = 1, outline = true } = {}) {
  const [cx, cy] = view.toPx(position);
  const length = Math.max(style.length_m * view.scale, 10);
  const width = Math.max(style.width_m * view.scale, 10);
  ctx.save();
  ctx.globalAlpha = alpha;
  ctx.translate(cx, cy);
  ctx.fillStyle = style.hatched ? stripes(ctx, style.color) : style.color;
  ctx.strokeStyle = "#111111";
  ctx.lineWidth = outline ? 1.5 : 0;
  ctx.beginPath();
  if (style.kind === "car") {
    ctx.rotate(heading || 0);
    ctx.rect(-length / 2, -width / 2, length, width);
    ctx.fill();
    if (outline) ctx.stroke();
    ctx.fillStyle = "#111111";
    ctx.beginPath(); // nose wedge shows the heading
    ctx.moveTo(length / 2, 0);
    ctx.lineTo(length / 2 - Math.min(width, length / 3), -width / 2);
    ctx.lineTo(length / 2 - Math.min(width, length / 3), width / 2);
    ctx.closePath();
    ctx.fill();
  } else {
    ctx.arc(0, 0, length / 2, 0, 2 * Math.PI);
    ctx.fill();
    if (outline) ctx.stroke();
    if (heading !== undefined && heading !== null) {
      ctx.rotate(heading);
      ctx.strokeStyle = "#111111";
      ctx.lineWidth = 2;
      ctx.beginPath();
      ctx.moveTo(0, 0);
      ctx.lineTo(length / 2, 0);
      ctx.stroke();
    }
  }
  ctx.restore();
  ctx.save();
  ctx.globalAlpha = alpha;
  const tagY = cy - Math.max(width, length) / 2 - 10;
  label(ctx, style.tag, cx, tagY, style.color === HUMAN_COLOR ? "#7a4f00" : style.color, 12);
  ctx.restore();
}

/** A polyline through scene points, in the agent's colour (dashed for the human). */
export function drawTrace(ctx, view, style, points, { alpha = 0.8, dots = false, width = 2.5 } = {}) {
  if (points.length < 2) return;
  ctx.save();
  ctx.globalAlpha = alpha;
  ctx.strokeStyle = style.color;
  ctx.lineWidth = width;
  ctx.setLineDash(style.hatched ? [6, 4] : []);
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
