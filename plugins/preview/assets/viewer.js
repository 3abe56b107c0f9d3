// Lamina's layer viewer: draws the layers pushed into LAYERS by the page, with a
// slider, zoom (wheel) and pan (drag), the composition of the region under the pointer,
// and toggles for toolpaths and tools. No network access: everything is in the page.
(function () {
  "use strict";
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const slider = document.getElementById("layer");
  const label = document.getElementById("label");
  const tip = document.getElementById("tip");
  const showPaths = document.getElementById("paths");
  const toolsBox = document.getElementById("tools");
  let current = 0;
  const view = { scale: 1, ox: 0, oy: 0 };

  const bounds = [Infinity, Infinity, -Infinity, -Infinity];
  const tools = new Set();
  for (const L of LAYERS) {
    for (const p of L.parts) {
      for (const c of p.contours) {
        for (let i = 0; i < c.length; i += 2) {
          bounds[0] = Math.min(bounds[0], c[i]);
          bounds[1] = Math.min(bounds[1], c[i + 1]);
          bounds[2] = Math.max(bounds[2], c[i]);
          bounds[3] = Math.max(bounds[3], c[i + 1]);
        }
      }
    }
    for (const t of L.paths) tools.add(t.tool);
  }
  const hiddenTools = new Set();
  for (const t of [...tools].sort((a, b) => a - b)) {
    const l = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.checked = true;
    box.dataset.tool = t;
    box.addEventListener("change", () => {
      if (box.checked) hiddenTools.delete(t); else hiddenTools.add(t);
      draw();
    });
    l.append(box, " tool " + t);
    toolsBox.append(l);
  }
  if (tools.size === 0) showPaths.parentElement.style.display = "none";

  function resize() {
    const dpr = window.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(canvas.clientWidth * dpr));
    canvas.height = Math.max(1, Math.round(canvas.clientHeight * dpr));
  }

  function fit() {
    const bar = document.getElementById("bar").offsetHeight + 10;
    const w = canvas.clientWidth, h = canvas.clientHeight - bar;
    if (!(bounds[0] <= bounds[2])) { view.scale = 1; view.ox = w / 2; view.oy = h / 2; return; }
    const bw = Math.max(bounds[2] - bounds[0], 1e-6), bh = Math.max(bounds[3] - bounds[1], 1e-6);
    view.scale = 0.9 * Math.min(w / bw, h / bh);
    view.ox = w / 2 - view.scale * (bounds[0] + bounds[2]) / 2;
    view.oy = bar + h / 2 + view.scale * (bounds[1] + bounds[3]) / 2;
  }

  function toModel(sx, sy) { return [(sx - view.ox) / view.scale, (view.oy - sy) / view.scale]; }

  function ringPath(c) {
    ctx.moveTo(view.ox + c[0] * view.scale, view.oy - c[1] * view.scale);
    for (let i = 2; i < c.length; i += 2) ctx.lineTo(view.ox + c[i] * view.scale, view.oy - c[i + 1] * view.scale);
    ctx.closePath();
  }

  function draw() {
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#f4f4f2";
    ctx.fillRect(0, 0, canvas.clientWidth, canvas.clientHeight);
    const L = LAYERS[current];
    if (!L) return;
    for (const p of L.parts) {
      for (const r of p.regions) {
        ctx.beginPath();
        for (const c of r.rings) ringPath(c);
        ctx.fillStyle = r.c;
        ctx.fill("evenodd");
      }
      ctx.beginPath();
      for (const c of p.contours) ringPath(c);
      ctx.strokeStyle = "#000";
      ctx.lineWidth = 1;
      ctx.stroke();
    }
    if (showPaths.checked) {
      for (const t of L.paths) {
        if (hiddenTools.has(t.tool) || t.pts.length < 4) continue;
        ctx.beginPath();
        ctx.moveTo(view.ox + t.pts[0] * view.scale, view.oy - t.pts[1] * view.scale);
        for (let i = 2; i < t.pts.length; i += 2) ctx.lineTo(view.ox + t.pts[i] * view.scale, view.oy - t.pts[i + 1] * view.scale);
        ctx.setLineDash(t.kind === "t" ? [4, 4] : []);
        ctx.strokeStyle = t.kind === "t" ? "#888" : "hsl(" + (t.tool * 97 % 360) + ",70%,35%)";
        ctx.lineWidth = 1;
        ctx.stroke();
      }
      ctx.setLineDash([]);
    }
  }

  function inside(rings, x, y) {
    let odd = false;
    for (const c of rings) {
      const n = c.length / 2;
      for (let i = 0, j = n - 1; i < n; j = i++) {
        const xi = c[2 * i], yi = c[2 * i + 1], xj = c[2 * j], yj = c[2 * j + 1];
        if ((yi > y) !== (yj > y) && x < (xj - xi) * (y - yi) / (yj - yi) + xi) odd = !odd;
      }
    }
    return odd;
  }

  /** The region of the shown layer at model point (x, y), with its part's name. */
  function regionAt(x, y) {
    const L = LAYERS[current];
    if (!L) return null;
    for (const p of L.parts) {
      for (const r of p.regions) {
        if (inside(r.rings, x, y)) return { part: LAMINA.parts[p.part].name, index: r.k, level: r.l, composition: r.m };
      }
    }
    return null;
  }

  function show(i) {
    current = Math.max(0, Math.min(LAYERS.length - 1, i | 0));
    slider.value = current;
    const L = LAYERS[current];
    label.textContent = L
      ? "layer " + L.i + " of " + LAMINA.layer_count + ", z = " + L.z + " mm (" + L.t + " mm thick)"
      : "no layers";
    draw();
  }

  slider.max = Math.max(0, LAYERS.length - 1);
  slider.addEventListener("input", () => show(+slider.value));
  showPaths.addEventListener("change", draw);
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    const k = Math.exp(-e.deltaY * 0.0015);
    view.ox = e.offsetX - (e.offsetX - view.ox) * k;
    view.oy = e.offsetY - (e.offsetY - view.oy) * k;
    view.scale *= k;
    draw();
  }, { passive: false });
  let drag = null;
  canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; canvas.classList.add("dragging"); });
  window.addEventListener("mouseup", () => { drag = null; canvas.classList.remove("dragging"); });
  canvas.addEventListener("mousemove", (e) => {
    if (drag) {
      view.ox += e.clientX - drag[0];
      view.oy += e.clientY - drag[1];
      drag = [e.clientX, e.clientY];
      draw();
    }
    const [x, y] = toModel(e.offsetX, e.offsetY);
    const r = regionAt(x, y);
    if (r) {
      tip.style.display = "block";
      tip.style.left = e.clientX + 14 + "px";
      tip.style.top = e.clientY + 14 + "px";
      tip.textContent = r.part + ", region " + r.index + " (r = " + r.level + ")\n" + r.composition;
    } else {
      tip.style.display = "none";
    }
  });
  canvas.addEventListener("mouseleave", () => { tip.style.display = "none"; });
  window.addEventListener("resize", () => { resize(); fit(); draw(); });
  document.addEventListener("keydown", (e) => {
    if (e.key === "ArrowUp" || e.key === "PageUp") show(current + 1);
    if (e.key === "ArrowDown" || e.key === "PageDown") show(current - 1);
  });

  resize();
  fit();
  show(0);

  window.lamina = { show, regionAt, layer: () => current, label: () => label.textContent };

  // Scripted checks for tests: #test:layer=3;at=1.5,2.0 moves the slider, then looks up
  // the region at a model point, and writes what the page shows into #test-result.
  if (location.hash.startsWith("#test:")) {
    const args = {};
    for (const kv of location.hash.slice(6).split(";")) {
      const [k, v] = kv.split("=");
      args[k] = v;
    }
    if (args.layer !== undefined) {
      slider.value = args.layer;
      slider.dispatchEvent(new Event("input"));
    }
    let region = null;
    if (args.at) {
      const [x, y] = args.at.split(",").map(Number);
      region = regionAt(x, y);
    }
    const out = document.getElementById("test-result");
    out.textContent = JSON.stringify({ layer: current, label: label.textContent, region, layers: LAYERS.length });
    out.hidden = false;
  }
})();
