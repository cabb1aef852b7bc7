// The floorplan drawing: rooms, each fragment's wall chain moved by its pose (site frame seen
// from above, x right, y up), its label at its walls, and a scale bar. Mirrors
// api/floorplan_svg.py.
"use strict";

const Plan = (() => {
  const WIDTH = 800;
  const HEIGHT = 600;
  const MARGIN = 40;
  const LABEL_GAP = 8; // px between a wall and its label
  const BAR_MAX_PX = 160;

  // p_site = pose · [p_local, 1], keeping x and y (keypoints are at floor height).
  function toSite(pose, point) {
    const [x, y, z] = point;
    return [
      pose[0][0] * x + pose[0][1] * y + pose[0][2] * z + pose[0][3],
      pose[1][0] * x + pose[1][1] * y + pose[1][2] * z + pose[1][3],
    ];
  }

  // The assembly to draw: choice 0 is the main one, k > 0 the k-th alternative.
  function assembly(result, choice) {
    const chains = new Map();
    const keypoints = new Map(result.fragments.map((f) => [f.id, f.local_layout?.keypoints || []]));
    let rooms = result.floorplan?.rooms || [];
    let placed = result.fragments.filter((f) => f.placed && f.pose).map((f) => [f.id, f.pose]);
    if (choice > 0) {
      const alternative = result.alternatives[choice - 1];
      rooms = alternative.floorplan?.rooms || [];
      placed = (alternative.fragments || []).filter((f) => f.pose).map((f) => [f.id, f.pose]);
    }
    for (const [id, pose] of placed) {
      const chain = (keypoints.get(id) || []).map((p) => toSite(pose, p));
      if (chain.length) chains.set(id, chain);
    }
    return { chains, rooms: rooms.map((r) => r.polygon || []).filter((p) => p.length >= 3) };
  }

  function viewOf(points) {
    const xs = points.map((p) => p[0]);
    const ys = points.map((p) => p[1]);
    const low = [Math.min(...xs), Math.min(...ys)];
    const span = [Math.max(...xs) - low[0] || 1, Math.max(...ys) - low[1] || 1];
    const scale = Math.min((WIDTH - 2 * MARGIN) / span[0], (HEIGHT - 2 * MARGIN) / span[1]);
    const offset = [(WIDTH - span[0] * scale) / 2, (HEIGHT - span[1] * scale) / 2];
    const px = ([x, y]) => [offset[0] + (x - low[0]) * scale, HEIGHT - offset[1] - (y - low[1]) * scale];
    return { px, scale };
  }

  function pathOf(points, view) {
    return points.map((p) => view.px(p).map((v) => v.toFixed(1)).join(",")).join(" ");
  }

  // 1, 2 or 5 x 10^k meters, the longest not above `meters`.
  function niceLength(meters) {
    const power = 10 ** Math.floor(Math.log10(meters));
    for (const step of [5, 2, 1]) if (step * power <= meters * (1 + 1e-9)) return step * power;
    return power;
  }

  // Where a label goes, in pixels: beside the middle of the fragment's longest wall, on the
  // side of `towards` (the middle of all the walls, inside the room). As api/floorplan_svg.py.
  function labelPlace(chain, towards) {
    let best = [chain[0], chain[0]];
    let longest = -1;
    for (let i = 0; i + 1 < chain.length; i += 1) {
      const length = Math.hypot(chain[i + 1][0] - chain[i][0], chain[i + 1][1] - chain[i][1]);
      if (length > longest) [longest, best] = [length, [chain[i], chain[i + 1]]];
    }
    const [a, b] = best;
    const middle = [(a[0] + b[0]) / 2, (a[1] + b[1]) / 2];
    if (Math.abs(b[0] - a[0]) < Math.abs(b[1] - a[1])) {
      const side = towards[0] >= middle[0] ? 1 : -1;
      return { x: middle[0] + side * LABEL_GAP, y: middle[1] + 4, anchor: side > 0 ? "start" : "end" };
    }
    const side = towards[1] >= middle[1] ? 1 : -1;
    return { x: middle[0], y: middle[1] + (side > 0 ? LABEL_GAP + 10 : -LABEL_GAP), anchor: "middle" };
  }

  function scaleBar(view) {
    const meters = niceLength(BAR_MAX_PX / view.scale);
    const pixels = meters * view.scale;
    const x = 12;
    const y = HEIGHT - 14;
    const group = FPJ.svg("g", { class: "scale-bar" });
    group.append(
      FPJ.svg("path", {
        d: `M${x},${y - 6} V${y} H${(x + pixels).toFixed(1)} V${y - 6}`,
        fill: "none",
        stroke: "#000",
        "stroke-width": 2,
      }),
      FPJ.svg("text", { id: "scale-text", x: (x + pixels / 2).toFixed(1), y: y - 9, "text-anchor": "middle" }, `${Number(meters.toPrecision(3))} m`),
    );
    return group;
  }

  // Draw `result` (choice: 0 main assembly, k the k-th alternative) into the <svg> element.
  // Returns the number of fragments drawn.
  function draw(svg, result, choice) {
    svg.replaceChildren();
    const { chains, rooms } = result ? assembly(result, choice) : { chains: new Map(), rooms: [] };
    const points = [...rooms.flat(), ...[...chains.values()].flat()];
    if (!points.length) return 0;
    const view = viewOf(points);
    for (const room of rooms) {
      svg.append(FPJ.svg("polygon", { class: "room", points: pathOf(room, view) }));
    }
    const pixels = [...chains.values()].flat().map(view.px);
    const middle = [0, 1].map((k) => pixels.reduce((sum, p) => sum + p[k], 0) / pixels.length);
    for (const [id, chain] of chains) {
      const color = FPJ.fragmentColor(id);
      const line = FPJ.svg("polyline", { class: "wall", points: pathOf(chain, view), stroke: color, "data-fragment": id });
      line.append(FPJ.svg("title", {}, id));
      const place = labelPlace(chain.map(view.px), middle);
      const label = FPJ.svg("text", { class: "label", x: place.x.toFixed(1), y: place.y.toFixed(1), "text-anchor": place.anchor, fill: color, "data-fragment": id }, id);
      svg.append(line, label);
    }
    svg.append(scaleBar(view));
    return chains.size;
  }

  return { draw, niceLength };
})();
