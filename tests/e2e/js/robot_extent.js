// Along a line through the robot's centre (x0, y0) in direction (dx, dy), within +-reach
// CSS px: the outermost offsets whose pixel is the robot's colour (within a tolerance).
([x0, y0, dx, dy, reach, color]) => {
  const canvas = document.querySelector("#trial-canvas");
  const dpr = canvas.width / canvas.clientWidth;
  const ctx = canvas.getContext("2d");
  const hit = (d) => {
    const x = Math.round((x0 + d * dx) * dpr);
    const y = Math.round((y0 + d * dy) * dpr);
    const px = ctx.getImageData(x, y, 1, 1).data;
    const off = Math.abs(px[0] - color[0]) + Math.abs(px[1] - color[1]) + Math.abs(px[2] - color[2]);
    return off < 60;
  };
  const found = [];
  for (let d = -reach; d <= reach; d += 0.25) if (hit(d)) found.push(d);
  return found.length ? [Math.min(...found), Math.max(...found)] : null;
}
