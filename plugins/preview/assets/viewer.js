// Lamina's layer viewer: draws the layers pushed into LAYERS by the page, with a
// slider, zoom (wheel) and pan (drag), the composition of the region under the pointer,
// the cursor's coordinates, a scale bar, and toggles for toolpaths and tools; with the
// machine's moves read back from the run's G-code (MOVES), a player that shows every
// head moving in time, both at once on machines with several motion systems. No
// network access: everything is in the page.
//
// A layer's geometry arrives packed (see `pack.rs`): base64 of zigzag varints, steps on
// a grid of 10^-digits mm. It is decoded only when the layer is shown, and a few decoded
// layers are kept, so a page of hundreds of layers opens as fast as one of a few.
(function () {
  "use strict";
  const canvas = document.getElementById("view");
  const ctx = canvas.getContext("2d");
  const slider = document.getElementById("layer");
  const label = document.getElementById("label");
  const tip = document.getElementById("tip");
  const cursor = document.getElementById("cursor");
  const showPaths = document.getElementById("paths");
  const toolsBox = document.getElementById("tools");
  const opsBox = document.getElementById("opsbox");
  const showOps = document.getElementById("ops");
  const opSelect = document.getElementById("op");
  const opList = document.getElementById("oplist");
  let current = 0;
  const view = { scale: 1, ox: 0, oy: 0 };
  const unit = Math.pow(10, -LAMINA.digits);

  // ---- decoding ------------------------------------------------------------------

  /** Reads the varints of one base64 block. */
  function reader(text) {
    const raw = atob(text);
    const bytes = new Uint8Array(raw.length);
    for (let i = 0; i < raw.length; i++) bytes[i] = raw.charCodeAt(i);
    let at = 0;
    let x = 0, y = 0, t = 0;
    const r = {
      more: () => at < bytes.length,
      uint() {
        // Arithmetic, not bit operations: a value may exceed 32 bits.
        let v = 0, mul = 1, b;
        do {
          b = bytes[at++];
          v += (b & 0x7f) * mul;
          mul *= 128;
        } while (b >= 0x80 && at < bytes.length);
        return v;
      },
      int() {
        const v = r.uint();
        return v % 2 ? -(v + 1) / 2 : v / 2;
      },
      /** A run of timed points: positions (mm) and times (ms). */
      timed() {
        const n = r.uint();
        const pts = new Float64Array(2 * n), ts = new Float64Array(n);
        for (let i = 0; i < n; i++) {
          x += r.int();
          y += r.int();
          t += r.int();
          pts[2 * i] = x * unit;
          pts[2 * i + 1] = y * unit;
          ts[i] = t;
        }
        return { pts, ts };
      },
      /** A run of points, as a flat array of millimetres. */
      points() {
        const n = r.uint();
        const out = new Float64Array(2 * n);
        for (let i = 0; i < n; i++) {
          x += r.int();
          y += r.int();
          out[2 * i] = x * unit;
          out[2 * i + 1] = y * unit;
        }
        return out;
      },
    };
    return r;
  }

  function ringBox(rings) {
    const b = [Infinity, Infinity, -Infinity, -Infinity];
    for (const c of rings) {
      for (let i = 0; i < c.length; i += 2) {
        if (c[i] < b[0]) b[0] = c[i];
        if (c[i + 1] < b[1]) b[1] = c[i + 1];
        if (c[i] > b[2]) b[2] = c[i];
        if (c[i + 1] > b[3]) b[3] = c[i + 1];
      }
    }
    return b;
  }

  function ringsPath(rings, closed) {
    const p = new Path2D();
    for (const c of rings) {
      if (c.length < 2) continue;
      p.moveTo(c[0], c[1]);
      for (let i = 2; i < c.length; i += 2) p.lineTo(c[i], c[i + 1]);
      if (closed) p.closePath();
    }
    return p;
  }

  const KINDS = ["e", "t", "p"];
  const cache = new Map();
  const CACHED = 12;

  /** The shown form of layer `i`: rings as arrays, and Path2D objects to draw. */
  /** Layer `i`'s parts as arrays: contours and each region's rings (mm). */
  function ringsOf(i) {
    const out = [];
    for (const p of LAYERS[i].parts) {
      const r = reader(p.g);
      const contours = [];
      for (let k = 0; k < p.nc; k++) contours.push(r.points());
      const regions = p.regions.map((meta) => {
        const rings = [];
        for (let k = 0; k < meta.n; k++) rings.push(r.points());
        return { meta, rings };
      });
      out.push({ part: p.part, contours, regions });
    }
    return out;
  }

  function decoded(i) {
    let d = cache.get(i);
    if (d) {
      cache.delete(i);
      cache.set(i, d);
      return d;
    }
    const L = LAYERS[i];
    d = { parts: [], paths: [] };
    for (const p of ringsOf(i)) {
      const regions = p.regions.map((r) => ({ meta: r.meta, rings: r.rings, box: ringBox(r.rings), path: ringsPath(r.rings, true) }));
      d.parts.push({ part: p.part, outline: ringsPath(p.contours, true), regions });
    }
    if (L.p) {
      const r = reader(L.p);
      while (r.more()) {
        const head = r.uint();
        const pts = r.points();
        d.paths.push({ tool: Math.floor(head / 3), kind: KINDS[head % 3], pts });
      }
    }
    // One Path2D per tool and kind: a layer of thousands of beads draws in a few calls.
    const groups = new Map();
    for (const t of d.paths) {
      if (t.pts.length < 4) continue;
      const key = t.tool + t.kind;
      if (!groups.has(key)) groups.set(key, { tool: t.tool, kind: t.kind, rings: [] });
      groups.get(key).rings.push(t.pts);
    }
    d.pathGroups = [...groups.values()].map((g) => ({ tool: g.tool, kind: g.kind, path: ringsPath(g.rings, false) }));
    // The process operations' paths, one Path2D per operation.
    d.ops = (L.ops || []).map((o) => ({ meta: o, rings: [] }));
    if (L.q) {
      const r = reader(L.q);
      while (r.more()) {
        const k = Math.floor(r.uint() / 3);
        const pts = r.points();
        if (d.ops[k]) d.ops[k].rings.push(pts);
      }
    }
    for (const o of d.ops) o.path = ringsPath(o.rings, false);
    cache.set(i, d);
    if (cache.size > CACHED) cache.delete(cache.keys().next().value);
    return d;
  }

  // ---- the machine's moves (read back from the G-code by the exporter) ----------

  const movesCache = new Map();

  /** The moves of layer `i` (runs of one system, tool and kind, timed), or null. */
  function movesOf(i) {
    const L = LAYERS[i];
    if (!L || !MOVES.has(L.i)) return null;
    let m = movesCache.get(i);
    if (m) return m;
    const r = reader(MOVES.get(L.i));
    const runs = [];
    let duration = 0;
    while (r.more()) {
      const system = r.uint();
      const head = r.uint();
      const { pts, ts } = r.timed();
      if (ts.length) duration = Math.max(duration, ts[ts.length - 1]);
      runs.push({ system, tool: Math.floor(head / 3), kind: KINDS[head % 3], pts, ts });
    }
    const systems = new Map();
    for (const run of runs) {
      if (!systems.has(run.system)) systems.set(run.system, []);
      systems.get(run.system).push(run);
    }
    m = { runs, duration, systems };
    movesCache.set(i, m);
    if (movesCache.size > CACHED) movesCache.delete(movesCache.keys().next().value);
    return m;
  }

  /** Where each motion system's head is at time t (ms), and whether it is moving. */
  function heads(m, t) {
    const out = [];
    for (const [system, runs] of [...m.systems.entries()].sort((a, b) => a[0] - b[0])) {
      let at = null, moving = false, tool = runs[0].tool;
      for (const run of runs) {
        const ts = run.ts, n = ts.length;
        if (!n || ts[0] > t) { if (at === null) at = [run.pts[0], run.pts[1]]; break; }
        tool = run.tool;
        if (ts[n - 1] <= t) { at = [run.pts[2 * n - 2], run.pts[2 * n - 1]]; continue; }
        let lo = 0, hi = n - 1;
        while (hi - lo > 1) { const mid = (lo + hi) >> 1; if (ts[mid] <= t) lo = mid; else hi = mid; }
        const f = ts[hi] > ts[lo] ? (t - ts[lo]) / (ts[hi] - ts[lo]) : 1;
        at = [run.pts[2 * lo] + f * (run.pts[2 * hi] - run.pts[2 * lo]), run.pts[2 * lo + 1] + f * (run.pts[2 * hi + 1] - run.pts[2 * lo + 1])];
        moving = true;
        break;
      }
      out.push({ system, tool, at, moving });
    }
    return out;
  }

  /** The run drawn up to time t: its points until t, the last one interpolated. */
  function runUntil(path, run, t) {
    const ts = run.ts, p = run.pts;
    if (!ts.length || ts[0] > t) return;
    path.moveTo(p[0], p[1]);
    for (let i = 1; i < ts.length; i++) {
      if (ts[i] <= t) { path.lineTo(p[2 * i], p[2 * i + 1]); continue; }
      const f = ts[i] > ts[i - 1] ? (t - ts[i - 1]) / (ts[i] - ts[i - 1]) : 0;
      path.lineTo(p[2 * i - 2] + f * (p[2 * i] - p[2 * i - 2]), p[2 * i - 1] + f * (p[2 * i + 1] - p[2 * i - 1]));
      return;
    }
  }

  const player = document.getElementById("player");
  const showMoves = document.getElementById("moves");
  const playButton = document.getElementById("play");
  const timeSlider = document.getElementById("time");
  const speed = document.getElementById("speed");
  const clock = document.getElementById("clock");
  let playT = Infinity;
  let playing = null;

  function drawMoves(m, hair) {
    const t = Math.min(playT, m.duration);
    const done = new Map();
    for (const run of m.runs) {
      if (hiddenTools.has(run.tool)) continue;
      const key = run.tool + run.kind;
      if (!done.has(key)) done.set(key, { run, path: new Path2D() });
      runUntil(done.get(key).path, run, t);
    }
    if (t < m.duration) {
      // What is still to come, faint.
      ctx.globalAlpha = 0.18;
      for (const run of m.runs) {
        if (hiddenTools.has(run.tool) || run.kind === "t") continue;
        ctx.strokeStyle = toolColour(run.tool);
        ctx.lineWidth = hair;
        ctx.stroke(ringsPath([run.pts], false));
      }
      ctx.globalAlpha = 1;
    }
    for (const { run, path } of done.values()) {
      ctx.setLineDash(run.kind === "t" ? [4 * hair, 4 * hair] : []);
      ctx.strokeStyle = run.kind === "t" ? "#888" : toolColour(run.tool);
      ctx.lineWidth = run.kind === "t" ? hair : 2 * hair;
      ctx.stroke(path);
    }
    ctx.setLineDash([]);
    for (const h of heads(m, t)) {
      if (!h.at) continue;
      ctx.beginPath();
      ctx.arc(h.at[0], h.at[1], 5 * hair, 0, 2 * Math.PI);
      ctx.fillStyle = h.moving ? toolColour(h.tool) : "#fff";
      ctx.fill();
      ctx.strokeStyle = "#000";
      ctx.lineWidth = 1.5 * hair;
      ctx.stroke();
    }
    clock.textContent = "t = " + (t / 1000).toFixed(1) + " of " + (m.duration / 1000).toFixed(1) + " s";
  }

  function stop() {
    if (playing !== null) cancelAnimationFrame(playing);
    playing = null;
    playButton.textContent = "play";
  }

  function play() {
    const m = movesOf(current);
    if (!m) return;
    if (playing !== null) { stop(); return; }
    if (!(playT < m.duration)) playT = 0;
    playButton.textContent = "pause";
    let last = performance.now();
    const step = (now) => {
      playT += (now - last) * +speed.value;
      last = now;
      if (playT >= m.duration) { playT = m.duration; stop(); }
      timeSlider.value = Math.round(1000 * playT / Math.max(1, m.duration));
      redraw();
      if (playing !== null) playing = requestAnimationFrame(step);
    };
    playing = requestAnimationFrame(step);
  }

  if (MOVES.size > 0) {
    player.hidden = false;
    player.title = "moves read back from " + GCODE.file + (GCODE.systems > 1 ? " (" + GCODE.systems + " motion systems)" : "");
  }
  // ---- pages: a viewer larger than its page size is split into runs of layers ----

  const pagesBox = document.getElementById("pages");
  if (PAGES) {
    const link = (name, text) => {
      const a = document.createElement("a");
      a.href = encodeURIComponent(name);
      a.textContent = text;
      return a;
    };
    if (PAGES.prev) pagesBox.append(link(PAGES.prev, "\u25c0 earlier layers"), " ");
    pagesBox.append("page " + (PAGES.index + 1) + " of " + PAGES.count + " (layers " + PAGES.first + "-" + PAGES.last + ")");
    if (PAGES.next) pagesBox.append(" ", link(PAGES.next, "later layers \u25b6"));
    pagesBox.title = "pages of at most " + PAGES.page_mb + " MB (the viewer's page_mb)";
    pagesBox.hidden = false;
  }
  showMoves.addEventListener("change", () => { stop(); draw(); });
  playButton.addEventListener("click", play);
  timeSlider.addEventListener("input", () => {
    stop();
    const m = movesOf(current);
    playT = m ? m.duration * timeSlider.value / 1000 : Infinity;
    draw();
  });

  // ---- tools and legend ----------------------------------------------------------

  function toolColour(t) { return "hsl(" + (t * 97 % 360) + ",70%,35%)"; }

  const tools = new Map();
  for (const t of LAMINA.tools) tools.set(t.index, t.name);
  for (const L of LAYERS) for (const t of L.tools) if (!tools.has(t)) tools.set(t, "T" + t);
  const hiddenTools = new Set();
  for (const t of [...tools.keys()].sort((a, b) => a - b)) {
    const l = document.createElement("label");
    const box = document.createElement("input");
    box.type = "checkbox";
    box.checked = true;
    box.dataset.tool = t;
    box.addEventListener("change", () => {
      if (box.checked) hiddenTools.delete(t); else hiddenTools.add(t);
      draw();
    });
    const swatch = document.createElement("i");
    swatch.className = "swatch";
    swatch.style.background = toolColour(t);
    l.append(box, swatch, " " + tools.get(t));
    toolsBox.append(l);
  }
  if (tools.size === 0) showPaths.parentElement.style.display = "none";

  // ---- process operations ------------------------------------------------------

  const OP_COLOURS = { "end-mill": "#c0392b", spray: "#e67e22", grind: "#2c3e50", engrave: "#8e44ad", fill: "#16a085" };
  function opColour(label) { return OP_COLOURS[label.split("/")[0]] || "#555"; }
  if (LAYERS.some((L) => L.ops && L.ops.length)) opsBox.hidden = false;
  showOps.addEventListener("change", () => { opList.hidden = !showOps.checked || !opSelect.options.length; draw(); });
  opSelect.addEventListener("change", () => { listOps(); draw(); });

  /** The shown layer's operations in the list and the choice of the one drawn. */
  function listOps() {
    const L = LAYERS[current];
    const ops = (L && L.ops) || [];
    const chosen = opSelect.value;
    if (opSelect.dataset.layer !== String(current)) {
      opSelect.dataset.layer = String(current);
      opSelect.replaceChildren();
      if (ops.length) opSelect.append(new Option("all operations", "all"));
      ops.forEach((o, k) => opSelect.append(new Option((k + 1) + ". " + o.k, String(k))));
      if ([...opSelect.options].some((o) => o.value === chosen)) opSelect.value = chosen;
    }
    opList.replaceChildren();
    ops.forEach((o, k) => {
      const li = document.createElement("li");
      li.textContent = o.k + ": " + o.s;
      li.style.color = opColour(o.k);
      if (opSelect.value === "all" || opSelect.value === String(k)) li.className = "on";
      opList.append(li);
    });
    opList.hidden = !ops.length || !showOps.checked;
  }

  /** The operations drawn: all, or the one chosen; returns how many paths. */
  function drawOps(d, hair) {
    if (!showOps.checked || !d.ops.length) return 0;
    let n = 0;
    d.ops.forEach((o, k) => {
      if (opSelect.value !== "all" && opSelect.value !== String(k)) return;
      ctx.strokeStyle = opColour(o.meta.k);
      ctx.lineWidth = 1.5 * hair;
      ctx.setLineDash(o.meta.k.startsWith("spray") || o.meta.k.startsWith("fill") ? [3 * hair, 2 * hair] : []);
      ctx.stroke(o.path);
      n += o.rings.length;
    });
    ctx.setLineDash([]);
    return n;
  }
  let opPathsDrawn = 0;

  // ---- view ----------------------------------------------------------------------

  function resize() {
    const dpr = window.devicePixelRatio || 1;
    canvas.width = Math.max(1, Math.round(canvas.clientWidth * dpr));
    canvas.height = Math.max(1, Math.round(canvas.clientHeight * dpr));
  }

  function fit() {
    const bar = document.getElementById("bar").offsetHeight + 10;
    const w = canvas.clientWidth, h = canvas.clientHeight - bar;
    const b = LAMINA.bounds;
    if (!b) { view.scale = 1; view.ox = w / 2; view.oy = h / 2; return; }
    const bw = Math.max(b[2] - b[0], 1e-6), bh = Math.max(b[3] - b[1], 1e-6);
    view.scale = 0.9 * Math.min(w / bw, h / bh);
    view.ox = w / 2 - view.scale * (b[0] + b[2]) / 2;
    view.oy = bar + h / 2 + view.scale * (b[1] + b[3]) / 2;
  }

  function toModel(sx, sy) { return [(sx - view.ox) / view.scale, (view.oy - sy) / view.scale]; }

  /** A round length near `target` mm: 1, 2 or 5 times a power of ten. */
  function niceLength(target) {
    const p = Math.pow(10, Math.floor(Math.log10(target)));
    for (const m of [1, 2, 5]) if (m * p >= target) return m * p;
    return 10 * p;
  }

  function scaleBar(dpr) {
    const mm = niceLength(100 / view.scale);
    const px = mm * view.scale;
    const x = 16, y = canvas.clientHeight - 20;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.strokeStyle = "#222";
    ctx.lineWidth = 2;
    ctx.beginPath();
    ctx.moveTo(x, y - 5); ctx.lineTo(x, y); ctx.lineTo(x + px, y); ctx.lineTo(x + px, y - 5);
    ctx.stroke();
    ctx.fillStyle = "#222";
    ctx.font = "12px system-ui, sans-serif";
    ctx.fillText((mm >= 1 ? mm : mm.toPrecision(1)) + " mm", x + 4, y - 6);
  }

  function draw() {
    const dpr = window.devicePixelRatio || 1;
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    ctx.fillStyle = "#f4f4f2";
    ctx.fillRect(0, 0, canvas.clientWidth, canvas.clientHeight);
    if (!LAYERS[current]) return;
    const d = decoded(current);
    // Model coordinates (mm, y up) straight onto the canvas.
    ctx.setTransform(dpr * view.scale, 0, 0, -dpr * view.scale, dpr * view.ox, dpr * view.oy);
    const hair = 1 / view.scale;
    for (const p of d.parts) {
      for (const r of p.regions) {
        ctx.fillStyle = r.meta.c;
        ctx.fill(r.path, "evenodd");
      }
      ctx.strokeStyle = "#000";
      ctx.lineWidth = hair;
      ctx.stroke(p.outline);
    }
    const m = MOVES.size > 0 && showMoves.checked ? movesOf(current) : null;
    if (m) {
      drawMoves(m, hair);
    } else if (showPaths.checked) {
      clock.textContent = "";
      for (const g of d.pathGroups) {
        if (hiddenTools.has(g.tool)) continue;
        ctx.setLineDash(g.kind === "t" ? [4 * hair, 4 * hair] : []);
        ctx.strokeStyle = g.kind === "t" ? "#888" : toolColour(g.tool);
        ctx.lineWidth = hair;
        ctx.stroke(g.path);
      }
      ctx.setLineDash([]);
    }
    opPathsDrawn = drawOps(d, hair);
    scaleBar(dpr);
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
    if (!LAYERS[current]) return null;
    for (const p of decoded(current).parts) {
      for (const r of p.regions) {
        const b = r.box;
        if (x < b[0] || x > b[2] || y < b[1] || y > b[3]) continue;
        if (inside(r.rings, x, y)) {
          return { part: LAMINA.parts[p.part].name, index: r.meta.k, level: r.meta.l, composition: r.meta.m };
        }
      }
    }
    return null;
  }

  function show(i) {
    const next = Math.max(0, Math.min(LAYERS.length - 1, i | 0));
    if (next !== current) { stop(); playT = Infinity; timeSlider.value = 1000; }
    current = next;
    slider.value = current;
    const L = LAYERS[current];
    label.textContent = L
      ? "layer " + L.i + " of " + LAMINA.layer_count + ", z = " + L.z + " mm (" + L.t + " mm thick)" +
        (PAGES && PAGES.moves_left_out && !MOVES.has(L.i) ? "; its machine moves are left out of this page (page_mb)" : "")
      : "no layers";
    listOps();
    if (in3d) v3.draw(); else draw();
  }

  // ---- the 3D view (view3d.js) -------------------------------------------------

  const v3dBox = document.getElementById("v3d");
  const cutBox = document.getElementById("cutbox");
  const cutOn = document.getElementById("cut");
  const cutAt = document.getElementById("cutat");
  const v3 = window.Lamina3D
    ? window.Lamina3D({ layers: LAYERS, rings: ringsOf, bounds: LAMINA.bounds, current: () => current })
    : null;
  let in3d = false;
  function set3d(on) {
    in3d = on && !!v3 && v3.open();
    if (!in3d && v3) v3.close();
    v3dBox.checked = in3d;
    canvas.hidden = in3d;
    cutBox.hidden = !in3d;
    if (!in3d) {
      // A window resized while the layer view was hidden left it without a size.
      resize();
      if (!(view.scale > 0)) fit();
      draw();
    }
  }
  function redraw() { if (in3d) v3.draw(); else draw(); }
  v3dBox.addEventListener("change", () => set3d(v3dBox.checked));
  const cutChanged = () => { if (v3) v3.setCut(cutOn.checked, +cutAt.value / 1000); };
  cutOn.addEventListener("change", cutChanged);
  cutAt.addEventListener("input", cutChanged);

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
    cursor.textContent = "x " + x.toFixed(2) + "  y " + y.toFixed(2) + " mm";
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
  canvas.addEventListener("mouseleave", () => { tip.style.display = "none"; cursor.textContent = ""; });
  window.addEventListener("resize", () => {
    if (!in3d) { resize(); fit(); }
    redraw();
  });
  document.addEventListener("keydown", (e) => {
    if (e.key === "ArrowUp" || e.key === "PageUp") show(current + 1);
    if (e.key === "ArrowDown" || e.key === "PageDown") show(current - 1);
  });

  resize();
  fit();
  show(0);
  const ready = performance.now();

  window.lamina = { show, regionAt, layer: () => current, label: () => label.textContent };

  // Scripted checks for tests: #test:layer=3;at=1.5,2.0;walk=1 moves the slider, looks up
  // the region at a model point, optionally shows every layer once (to time it), and
  // writes what the page shows into #test-result.
  if (location.hash.startsWith("#test:")) {
    const args = {};
    for (const kv of location.hash.slice(6).split(";")) {
      const [k, v] = kv.split("=");
      args[k] = v;
    }
    let walk = null;
    if (args.walk) {
      const t0 = performance.now();
      for (let i = 0; i < LAYERS.length; i++) show(i);
      walk = (performance.now() - t0) / Math.max(1, LAYERS.length);
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
    let view3d = null;
    if (args.view === "3d") {
      set3d(true);
      if (in3d) {
        if (args.camera) v3.camera(args.camera);
        if (args.cut !== undefined) {
          cutOn.checked = true;
          cutAt.value = Math.round(1000 * +args.cut);
          cutChanged();
        }
        view3d = { stats: v3.stats() };
        if (args.probe) {
          const [x, y] = args.probe.split(",").map(Number);
          view3d.probe = v3.pixelAt(x, y, LAYERS[current].z);
          // A second point, e.g. across the cut plane.
          if (args.probe2) {
            const [x2, y2] = args.probe2.split(",").map(Number);
            view3d.probe2 = v3.pixelAt(x2, y2, LAYERS[current].z);
          }
        }
      } else {
        view3d = { error: "no WebGL" };
      }
    }
    if (args.op !== undefined) {
      opSelect.value = args.op;
      opSelect.dispatchEvent(new Event("change"));
    }
    const operations = (LAYERS[current] && LAYERS[current].ops || []).map((o) => o.k);
    let moves = null;
    const m = movesOf(current);
    if (m) {
      if (args.t !== undefined) {
        playT = m.duration * +args.t;
        timeSlider.value = Math.round(1000 * +args.t);
        draw();
      }
      const extruded = {};
      for (const run of m.runs) {
        if (run.kind !== "e") continue;
        let len = 0;
        for (let i = 2; i < run.pts.length; i += 2) len += Math.hypot(run.pts[i] - run.pts[i - 2], run.pts[i + 1] - run.pts[i - 1]);
        extruded[run.tool] = (extruded[run.tool] || 0) + len;
      }
      // Time during which every motion system is moving at once, sampled.
      let together = 0;
      const samples = 400;
      for (let k = 0; k < samples; k++) {
        const hs = heads(m, (k + 0.5) * m.duration / samples);
        if (hs.length > 1 && hs.every((h) => h.moving)) together++;
      }
      moves = {
        runs: m.runs.length,
        systems: m.systems.size,
        duration_s: m.duration / 1000,
        extruded_mm: extruded,
        heads: heads(m, Math.min(playT, m.duration)),
        together: together / samples,
        clock: clock.textContent,
      };
    }
    const out = document.getElementById("test-result");
    out.textContent = JSON.stringify({
      layer: current,
      label: label.textContent,
      region,
      layers: LAYERS.length,
      pages: PAGES,
      tools: [...tools.values()],
      ready_ms: ready,
      walk_ms_per_layer: walk,
      moves,
      view3d,
      operations,
      op_paths_drawn: opPathsDrawn,
      op_list: [...opList.children].map((li) => li.textContent),
    });
    out.hidden = false;
  }
})();
