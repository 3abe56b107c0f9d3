// Lamina's 3D view of the graded part: the layer stack as extruded sub-regions, each in
// its composition's colour, in WebGL 1 with no library. Orbit (drag), zoom (wheel), a
// cut plane across X, and the layer slider hides everything above the shown layer,
// whose sub-regions are drawn as its exact top face.
//
// Walls: every ring of every sub-region becomes a vertical band from the layer below to
// the layer's z, set in by a hair toward its own region so that the shared boundary of
// two neighbours shows both colours through the cut rather than flickering. On large
// plans only every n-th layer is built (each then stands as tall as the layers it
// stands for), so the wall count stays near WALL_BUDGET edges.
// Top face: the shown layer's sub-regions filled with the stencil buffer's even-odd
// rule (a triangle fan over every edge, counted by inverting the stencil, then the
// colour where the count is odd), so no triangulation of polygons with holes is needed.
window.Lamina3D = function (api) {
  "use strict";
  const WALL_BUDGET = 400000;
  const canvas = document.getElementById("view3d");
  let gl = null, prog = null, loc = null, walls = null, cap = null, capLayer = -1;
  const cam = { yaw: -2.2, pitch: 0.55, dist: 1, target: [0, 0, 0] };
  const cut = { on: false, at: 0.5 };

  const VS = "attribute vec3 p; attribute vec3 c; uniform mat4 m; varying vec3 vp; varying vec3 vc;" +
    "void main() { vp = p; vc = c; gl_Position = m * vec4(p, 1.0); }";
  const FS = (lit) => (lit ? "#extension GL_OES_standard_derivatives : enable\n" : "") +
    "precision highp float; varying vec3 vp; varying vec3 vc; uniform float top; uniform vec4 plane; uniform float shade;" +
    "void main() {" +
    " if (vp.z > top) discard;" +
    " if (plane.w > 0.5 && vp.x > plane.x) discard;" +
    " float k = 1.0;" +
    (lit ? " if (shade > 0.5) { vec3 n = normalize(cross(dFdx(vp), dFdy(vp))); k = 0.55 + 0.45 * abs(dot(n, normalize(vec3(0.4, -0.6, 0.7)))); }" : "") +
    " gl_FragColor = vec4(vc * k, 1.0); }";

  function shader(type, text) {
    const s = gl.createShader(type);
    gl.shaderSource(s, text);
    gl.compileShader(s);
    if (!gl.getShaderParameter(s, gl.COMPILE_STATUS)) throw new Error(gl.getShaderInfoLog(s));
    return s;
  }

  function init() {
    if (gl) return true;
    gl = canvas.getContext("webgl", { stencil: true, antialias: true, preserveDrawingBuffer: true });
    if (!gl) return false;
    const lit = !!gl.getExtension("OES_standard_derivatives");
    prog = gl.createProgram();
    gl.attachShader(prog, shader(gl.VERTEX_SHADER, VS));
    gl.attachShader(prog, shader(gl.FRAGMENT_SHADER, FS(lit)));
    gl.linkProgram(prog);
    loc = {
      p: gl.getAttribLocation(prog, "p"),
      c: gl.getAttribLocation(prog, "c"),
      m: gl.getUniformLocation(prog, "m"),
      top: gl.getUniformLocation(prog, "top"),
      plane: gl.getUniformLocation(prog, "plane"),
      shade: gl.getUniformLocation(prog, "shade"),
    };
    const b = api.bounds || [0, 0, 1, 1];
    const zs = api.layers.map((L) => L.z);
    const ztop = zs.length ? Math.max(...zs) : 1;
    cam.target = [(b[0] + b[2]) / 2, (b[1] + b[3]) / 2, ztop / 2];
    cam.dist = 1.6 * Math.max(b[2] - b[0], b[3] - b[1], ztop, 1e-3);
    return true;
  }

  /** Vertices as 16 bytes each: x, y, z (float32) and r, g, b, 0 (bytes). */
  function vertexBuffer(n) {
    const buf = new ArrayBuffer(16 * n);
    return { f: new Float32Array(buf), u: new Uint8Array(buf), n: 0 };
  }

  function push(v, x, y, z, col) {
    const i = v.n++;
    v.f[4 * i] = x; v.f[4 * i + 1] = y; v.f[4 * i + 2] = z;
    v.u[16 * i + 12] = col[0]; v.u[16 * i + 13] = col[1]; v.u[16 * i + 14] = col[2];
  }

  function colour(hex) {
    return [1, 3, 5].map((k) => parseInt(hex.slice(k, k + 2), 16));
  }

  function upload(v) {
    const b = gl.createBuffer();
    gl.bindBuffer(gl.ARRAY_BUFFER, b);
    gl.bufferData(gl.ARRAY_BUFFER, v.f.buffer.slice(0, 16 * v.n), gl.STATIC_DRAW);
    return { buffer: b, count: v.n };
  }

  function signedArea(c) {
    let a = 0;
    for (let i = 0, n = c.length / 2, j = n - 1; i < n; j = i++) a += c[2 * j] * c[2 * i + 1] - c[2 * i] * c[2 * j + 1];
    return a / 2;
  }

  function buildWalls() {
    const t0 = performance.now();
    // About two bytes a point in the packed text: the layer stride from its length.
    let bytes = 0;
    for (const L of api.layers) for (const p of L.parts) bytes += p.g.length;
    const stride = Math.max(1, Math.ceil((bytes * 0.75 / 2) / WALL_BUDGET));
    const kept = [];
    for (let i = api.layers.length - 1; i >= 0; i -= stride) kept.unshift(i);
    const layers = kept.map((i) => ({ i, rings: api.rings(i) }));
    let edges = 0;
    for (const l of layers) for (const p of l.rings) for (const r of p.regions) for (const c of r.rings) edges += c.length / 2;
    const v = vertexBuffer(6 * edges);
    const hair = 0.002;
    let below = null;
    for (const l of layers) {
      const L = api.layers[l.i];
      const z1 = L.z, z0 = below === null ? L.z - L.t : below;
      below = z1;
      for (const p of l.rings) {
        for (const r of p.regions) {
          const col = colour(r.meta.c);
          r.rings.forEach((c, k) => {
            const n = c.length / 2;
            if (n < 3) return;
            // Left of the walk is this region's side for a counter-clockwise outer
            // ring and a clockwise hole.
            const left = (k === 0) === (signedArea(c) > 0) ? 1 : -1;
            for (let a = 0; a < n; a++) {
              const b = (a + 1) % n;
              const dx = c[2 * b] - c[2 * a], dy = c[2 * b + 1] - c[2 * a + 1];
              const len = Math.hypot(dx, dy) || 1;
              const ox = -dy / len * hair * left, oy = dx / len * hair * left;
              const ax = c[2 * a] + ox, ay = c[2 * a + 1] + oy, bx = c[2 * b] + ox, by = c[2 * b + 1] + oy;
              push(v, ax, ay, z0, col); push(v, bx, by, z0, col); push(v, bx, by, z1, col);
              push(v, ax, ay, z0, col); push(v, bx, by, z1, col); push(v, ax, ay, z1, col);
            }
          });
        }
      }
    }
    walls = upload(v);
    walls.stride = stride;
    walls.layers = kept.length;
    walls.ms = performance.now() - t0;
  }

  /** The shown layer's top face: per region, a fan from one point over all its edges. */
  function buildCap(i) {
    if (cap && capLayer === i) return;
    if (cap) gl.deleteBuffer(cap.buffer);
    const L = api.layers[i];
    const parts = api.rings(i);
    let edges = 0;
    for (const p of parts) for (const r of p.regions) for (const c of r.rings) edges += c.length / 2;
    const v = vertexBuffer(3 * edges);
    const ranges = [];
    for (const p of parts) {
      for (const r of p.regions) {
        if (!r.rings.length || r.rings[0].length < 6) continue;
        const col = colour(r.meta.c);
        const start = v.n;
        const ox = r.rings[0][0], oy = r.rings[0][1];
        for (const c of r.rings) {
          const n = c.length / 2;
          for (let a = 0; a < n; a++) {
            const b = (a + 1) % n;
            push(v, ox, oy, L.z, col);
            push(v, c[2 * a], c[2 * a + 1], L.z, col);
            push(v, c[2 * b], c[2 * b + 1], L.z, col);
          }
        }
        ranges.push([start, v.n - start]);
      }
    }
    cap = upload(v);
    cap.ranges = ranges;
    capLayer = i;
  }

  function matrix() {
    const w = canvas.width, h = canvas.height;
    const cp = Math.cos(cam.pitch), sp = Math.sin(cam.pitch);
    const eye = [
      cam.target[0] + cam.dist * cp * Math.cos(cam.yaw),
      cam.target[1] + cam.dist * cp * Math.sin(cam.yaw),
      cam.target[2] + cam.dist * sp,
    ];
    const sub = (a, b) => [a[0] - b[0], a[1] - b[1], a[2] - b[2]];
    const cross = (a, b) => [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]];
    const norm = (a) => { const l = Math.hypot(a[0], a[1], a[2]) || 1; return [a[0] / l, a[1] / l, a[2] / l]; };
    const dot = (a, b) => a[0] * b[0] + a[1] * b[1] + a[2] * b[2];
    const f = norm(sub(cam.target, eye));
    // Looking straight down, "up" on the screen is +y.
    const up = Math.abs(f[2]) > 0.999 ? [0, 1, 0] : [0, 0, 1];
    const s = norm(cross(f, up));
    const u = cross(s, f);
    const near = cam.dist / 100, far = cam.dist * 10;
    const t = 1 / Math.tan(0.4);
    const a = w / Math.max(1, h);
    // Column-major: projection times view.
    const view = [s[0], u[0], -f[0], 0, s[1], u[1], -f[1], 0, s[2], u[2], -f[2], 0, -dot(s, eye), -dot(u, eye), dot(f, eye), 1];
    const proj = [t / a, 0, 0, 0, 0, t, 0, 0, 0, 0, (far + near) / (near - far), -1, 0, 0, 2 * far * near / (near - far), 0];
    const m = new Float32Array(16);
    for (let c = 0; c < 4; c++) {
      for (let r = 0; r < 4; r++) {
        let v = 0;
        for (let k = 0; k < 4; k++) v += proj[k * 4 + r] * view[c * 4 + k];
        m[c * 4 + r] = v;
      }
    }
    return m;
  }

  function bind(b) {
    gl.bindBuffer(gl.ARRAY_BUFFER, b.buffer);
    gl.enableVertexAttribArray(loc.p);
    gl.vertexAttribPointer(loc.p, 3, gl.FLOAT, false, 16, 0);
    gl.enableVertexAttribArray(loc.c);
    gl.vertexAttribPointer(loc.c, 3, gl.UNSIGNED_BYTE, true, 16, 12);
  }

  function draw() {
    if (!gl) return;
    const dpr = window.devicePixelRatio || 1;
    const w = Math.max(1, Math.round(canvas.clientWidth * dpr)), h = Math.max(1, Math.round(canvas.clientHeight * dpr));
    if (canvas.width !== w || canvas.height !== h) { canvas.width = w; canvas.height = h; }
    if (!walls) buildWalls();
    const i = api.current();
    const L = api.layers[i];
    if (!L) return;
    buildCap(i);
    gl.viewport(0, 0, w, h);
    gl.clearColor(0.957, 0.957, 0.949, 1);
    gl.clearStencil(0);
    gl.clear(gl.COLOR_BUFFER_BIT | gl.DEPTH_BUFFER_BIT | gl.STENCIL_BUFFER_BIT);
    gl.enable(gl.DEPTH_TEST);
    gl.depthFunc(gl.LEQUAL);
    gl.useProgram(prog);
    gl.uniformMatrix4fv(loc.m, false, matrix());
    gl.uniform1f(loc.top, L.z + 1e-4);
    const b = api.bounds || [0, 0, 1, 1];
    gl.uniform4f(loc.plane, b[0] + cut.at * (b[2] - b[0]), 0, 0, cut.on ? 1 : 0);
    // Walls, shaded.
    gl.uniform1f(loc.shade, 1);
    bind(walls);
    gl.drawArrays(gl.TRIANGLES, 0, walls.count);
    // Top face, flat: the region's own colour, as in the layer view.
    gl.uniform1f(loc.shade, 0);
    bind(cap);
    gl.enable(gl.STENCIL_TEST);
    for (const [start, count] of cap.ranges) {
      gl.colorMask(false, false, false, false);
      gl.depthMask(false);
      gl.stencilFunc(gl.ALWAYS, 0, 0xff);
      gl.stencilOp(gl.KEEP, gl.KEEP, gl.INVERT);
      gl.drawArrays(gl.TRIANGLES, start, count);
      gl.colorMask(true, true, true, true);
      gl.depthMask(true);
      gl.stencilFunc(gl.NOTEQUAL, 0, 0xff);
      gl.stencilOp(gl.ZERO, gl.ZERO, gl.ZERO);
      gl.drawArrays(gl.TRIANGLES, start, count);
    }
    gl.disable(gl.STENCIL_TEST);
  }

  /** The colour drawn where model point (x, y, z) lands on the canvas, and the pixel. */
  function pixelAt(x, y, z) {
    const m = matrix();
    const c = [0, 1, 2, 3].map((r) => m[r] * x + m[4 + r] * y + m[8 + r] * z + m[12 + r]);
    const px = Math.round((c[0] / c[3] + 1) / 2 * canvas.width);
    const py = Math.round((c[1] / c[3] + 1) / 2 * canvas.height);
    const out = new Uint8Array(4);
    gl.readPixels(px, py, 1, 1, gl.RGBA, gl.UNSIGNED_BYTE, out);
    return { rgb: [out[0], out[1], out[2]], px: [px, canvas.height - py] };
  }

  let drag = null;
  canvas.addEventListener("mousedown", (e) => { drag = [e.clientX, e.clientY]; });
  window.addEventListener("mouseup", () => { drag = null; });
  canvas.addEventListener("mousemove", (e) => {
    if (!drag) return;
    cam.yaw -= (e.clientX - drag[0]) * 0.008;
    cam.pitch = Math.max(-1.55, Math.min(1.55, cam.pitch + (e.clientY - drag[1]) * 0.008));
    drag = [e.clientX, e.clientY];
    draw();
  });
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    cam.dist *= Math.exp(e.deltaY * 0.0015);
    draw();
  }, { passive: false });

  return {
    /** Shows the 3D view; false when the browser has no WebGL. */
    open() {
      canvas.hidden = false;
      if (!init()) { canvas.hidden = true; return false; }
      draw();
      return true;
    },
    close() { canvas.hidden = true; },
    draw,
    pixelAt,
    setCut(on, at) { cut.on = on; cut.at = at; draw(); },
    /** Named camera positions: `top` looks straight down, `front` along +y. */
    camera(name) {
      if (name === "top") { cam.pitch = Math.PI / 2 - 1e-4; cam.yaw = -Math.PI / 2; }
      if (name === "front") { cam.pitch = 0.0; cam.yaw = -Math.PI / 2; }
      draw();
    },
    stats: () => (walls ? { wall_triangles: walls.count / 3, layers_built: walls.layers, stride: walls.stride, build_ms: walls.ms } : null),
  };
};
