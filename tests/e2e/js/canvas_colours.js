// Every drawn thing a participant must see, drawn by the page's own code (scene.js) on each
// ground it can stand on (a simulated scene's, flat; a recorded scene's road and field, as
// drawBackground paints them); returns the pixels (RGBA) the test computes contrast from.
async () => {
  const s = await import("/static/js/scene.js");
  const pixel = (ctx, x, y) => Array.from(ctx.getImageData(Math.round(x), Math.round(y), 1, 1).data);
  const canvas = (w, h) => {
    const c = document.createElement("canvas");
    document.body.append(c);
    return [c, s.sizeCanvas(c, w, h)];
  };
  const disc = (i) => ({ ...s.agentStyle({ agents: [] }, i), kind: "disc", length_m: 2, width_m: 2 });
  const commonest = (ctx, x, y, w, h) => {  // the fill of a striped area: its commonest colour
    const counts = new Map();
    const data = ctx.getImageData(x, y, w, h).data;
    for (let i = 0; i < data.length; i += 4) {
      const key = `${data[i]},${data[i + 1]},${data[i + 2]}`;
      counts.set(key, (counts.get(key) || 0) + 1);
    }
    return [...counts.entries()].sort((a, b) => b[1] - a[1])[0][0].split(",").map(Number);
  };
  const flat = (colour) => (ctx) => {
    ctx.fillStyle = colour;
    ctx.fillRect(0, 0, 240, 160);
  };
  // a recorded scene over the whole canvas, driven everywhere (road) or nowhere (field)
  const recorded = (driven) => (ctx, view) => {
    const scene = {
      bounds: { x_min_m: -8, x_max_m: 8, y_min_m: -6, y_max_m: 6 }, agents: [],
      recorded: { view_span_m: 60, lines: [], driven: { cell_m: 2, x0_m: -8, y0_m: -6, runs: driven ? [0, 1, 2, 3, 4, 5].map((r) => [r, 0, 7]) : [] } },
    };
    s.drawBackground(ctx, view, scene, 0, { labels: false });
  };
  const grounds = Object.entries(s.GROUND).map(([name, colour]) => [name, flat(colour)]);
  grounds.push(["recorded road", recorded(true)], ["recorded field", recorded(false)]);
  const out = {};
  for (const [name, paint] of grounds) {
    const [c, ctx] = canvas(240, 160);
    const view = s.viewAt(20, [0, 0], 240, 160);
    paint(ctx, view);
    const at = (m) => pixel(ctx, ...view.toPx(m));
    s.drawAgent(ctx, view, disc(0), [-4, -1.5], 0, { tag: false });
    s.drawAgent(ctx, view, disc(1), [0, -1.5], null, { tag: false });
    s.drawTrace(ctx, view, disc(0), [[-5.5, 1.5], [5.5, 1.5]], { width: 2 });
    s.drawTrace(ctx, view, disc(1), [[-5.5, 3], [5.5, 3]], { width: 2 });
    s.drawRing(ctx, view, [4, -1.5]);
    s.drawAgent(ctx, view, disc(0), [4, 2.2], 0, { tag: false, seeThrough: true });
    out[name] = {
      ground: at([5.9, -3.9]), robot: at([-4, -1.2]), person: commonest(ctx, 100, 50, 40, 20),
      robot_trace: at([0, 1.5]), person_trace: at([-5.4, 3]), ring: at([4 + 7 / 20, -1.5]),
      robot_outline: at([4 - 1 - 0.02, 2.2]),
    };
    c.remove();
  }
  // goal rings at the clip's scale (about 60 px/m); each ring's most covered pixel in the
  // middle of its first dash (the stroke is thin, so its edge pixels are blends)
  const scale = 60;
  const [c, ctx] = canvas(10 * scale, 10 * scale);
  const goals = s.GOAL_COLORS.map((_, k) => ({ x_m: 2 + 2 * k, y_m: 5, radius_m: 0.8, label: "" }));
  const scene = { bounds: { x_min_m: 0, x_max_m: 10, y_min_m: 0, y_max_m: 10 }, lanes: [], obstacles: [], goals };
  const view = s.viewAt(scale, [5, 5], 10 * scale, 10 * scale);
  s.drawBackground(ctx, view, scene, 0, { labels: false });
  const darkest = (x, y) => {
    const around = [-1, 0, 1].flatMap((i) => [-1, 0, 1].map((j) => pixel(ctx, x + i, y + j)));
    return around.sort((a, b) => a[0] + a[1] + a[2] - (b[0] + b[1] + b[2]))[0];
  };
  out.goals = goals.map((g) => {
    const angle = 3 / (g.radius_m * scale);  // 3 px along the first 6 px dash
    return darkest(...view.toPx([g.x_m + g.radius_m * Math.cos(angle), g.y_m + g.radius_m * Math.sin(angle)]));
  });
  out.goal_ground = pixel(ctx, 5, 5);
  c.remove();
  return out;
}
