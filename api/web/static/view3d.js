// A small 3D view of the layout model (glTF from GET /v1/sites/{site}/layout.gltf) on a 2D
// canvas: painter's algorithm over the triangles, drag to turn. No WebGL, no library.
"use strict";

const View3D = (() => {
  function decode(gltf) {
    const uri = gltf.buffers[0].uri;
    const bytes = Uint8Array.from(atob(uri.slice(uri.indexOf(",") + 1)), (c) => c.charCodeAt(0));
    const [positions, indices] = gltf.accessors;
    const views = gltf.bufferViews;
    const vertices = new Float32Array(bytes.buffer, views[positions.bufferView].byteOffset, positions.count * 3);
    const triangles = new Uint32Array(bytes.buffer, views[indices.bufferView].byteOffset, indices.count);
    return { vertices, triangles }; // site frame: z up
  }

  function create(canvas) {
    const context = canvas.getContext("2d");
    let mesh = null;
    let yaw = -0.6;
    let pitch = 0.9;

    function render() {
      context.clearRect(0, 0, canvas.width, canvas.height);
      if (!mesh) return;
      const v = mesh.vertices;
      const n = v.length / 3;
      const centre = [0, 1, 2].map((k) => {
        let sum = 0;
        for (let i = 0; i < n; i += 1) sum += v[3 * i + k];
        return sum / n;
      });
      const [cy, sy, cp, sp] = [Math.cos(yaw), Math.sin(yaw), Math.cos(pitch), Math.sin(pitch)];
      const projected = [];
      let extent = 1e-6;
      for (let i = 0; i < n; i += 1) {
        const x = v[3 * i] - centre[0];
        const y = v[3 * i + 1] - centre[1];
        const z = v[3 * i + 2] - centre[2];
        const xr = cy * x - sy * y;
        const yr = sy * x + cy * y;
        const screen = [xr, -(cp * z + sp * yr), cp * yr - sp * z]; // right, down, depth
        extent = Math.max(extent, Math.abs(screen[0]), Math.abs(screen[1]));
        projected.push(screen);
      }
      const scale = (0.45 * Math.min(canvas.width, canvas.height)) / extent;
      let top = -Infinity;
      for (let i = 0; i < n; i += 1) top = Math.max(top, v[3 * i + 2]);
      const faces = [];
      for (let t = 0; t < mesh.triangles.length; t += 3) {
        const ids = [mesh.triangles[t], mesh.triangles[t + 1], mesh.triangles[t + 2]];
        if (ids.every((i) => v[3 * i + 2] > top - 1e-3)) continue; // no ceiling: look inside
        const corners = ids.map((i) => projected[i]);
        faces.push({ corners, depth: corners.reduce((sum, c) => sum + c[2], 0) / 3 });
      }
      faces.sort((a, b) => b.depth - a.depth);
      context.strokeStyle = "#555";
      context.fillStyle = "rgba(214, 214, 205, 0.85)";
      for (const face of faces) {
        context.beginPath();
        face.corners.forEach(([x, y], k) => {
          const px = canvas.width / 2 + x * scale;
          const py = canvas.height / 2 + y * scale;
          if (k === 0) context.moveTo(px, py);
          else context.lineTo(px, py);
        });
        context.closePath();
        context.fill();
        context.stroke();
      }
    }

    let dragging = null;
    canvas.addEventListener("pointerdown", (event) => {
      dragging = [event.clientX, event.clientY];
      canvas.setPointerCapture(event.pointerId);
    });
    canvas.addEventListener("pointerup", () => {
      dragging = null;
    });
    canvas.addEventListener("pointermove", (event) => {
      if (!dragging) return;
      yaw += (event.clientX - dragging[0]) * 0.01;
      pitch = Math.max(0, Math.min(Math.PI / 2, pitch + (event.clientY - dragging[1]) * 0.01));
      dragging = [event.clientX, event.clientY];
      render();
    });

    return {
      show(gltf) {
        mesh = gltf ? decode(gltf) : null;
        render();
      },
    };
  }

  return { create };
})();
