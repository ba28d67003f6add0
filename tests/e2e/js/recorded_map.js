// A recorded scene's map drawn by the page's own code (scene.js) at a scale where the 2 m
// cells end at fractions of a pixel: every pixel inside the driven block, and for each kind of
// map line the pixels across it and along it (RGB), for the test to read the styles from.
async () => {
  const s = await import("/static/js/scene.js");
  const [width, height, scale] = [400, 440, 13.7];
  const c = document.createElement("canvas");
  document.body.append(c);
  const ctx = s.sizeCanvas(c, width, height);
  const view = s.viewAt(scale, [0, 5], width, height);
  const lineY = { kerb: 11, border: 13, dashed: 15, virtual: 17, stop: 19 };
  const line = (kind, y, dashed = false) => ({ kind, dashed, points: [[-13, y], [13, y]] });
  const scene = {
    bounds: { x_min_m: -14, x_max_m: 14, y_min_m: -10, y_max_m: 20 }, agents: [],
    recorded: {
      view_span_m: 60,
      // rows of alternating length, so no two rows merge into one rectangle
      driven: { cell_m: 2, x0_m: -8, y0_m: -8, runs: [...Array(8).keys()].map((r) => [r, 0, 6 + (r % 2)]) },
      lines: [line("kerb", lineY.kerb), line("border", lineY.border), line("border", lineY.dashed, true),
        line("virtual", lineY.virtual), line("stop", lineY.stop)],
    },
  };
  s.drawBackground(ctx, view, scene, 0, { labels: false });
  const dpr = window.devicePixelRatio || 1;
  const rgb = (x, y) => Array.from(ctx.getImageData(Math.round(x * dpr), Math.round(y * dpr), 1, 1).data.slice(0, 3));
  const [x0, y0] = view.toPx([-8, -8]);
  const [x1, y1] = view.toPx([6, 8]); // columns 0-6 are driven in every row
  const block = [];
  for (let y = Math.ceil(y0) + 1; y < Math.floor(y1) - 1; y += 1) {
    for (let x = Math.ceil(x0) + 1; x < Math.floor(x1) - 1; x += 1) block.push(rgb(x, y));
  }
  const lines = {};
  for (const [name, y] of Object.entries(lineY)) {
    const [lx, ly] = view.toPx([-12, y]);
    lines[name] = {
      across: [...Array(21).keys()].map((k) => rgb(lx + 7, ly - 10 + k)), // at x = -11.5 m: painted
      along: [...Array(240).keys()].map((k) => rgb(lx + k, ly)),
    };
  }
  c.remove();
  return { block, lines, field: rgb(...view.toPx([12, 0])), palette: s.MAP };
}
