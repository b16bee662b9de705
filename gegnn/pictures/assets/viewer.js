// gegnn view: a mesh (or a point cloud) coloured by the geodesic field of one vertex, the field decoded in the
// page from the per-vertex codes of one forward pass with the model's own decoder (gegnn/decoders.py, the same
// formulas). Drawn by a small z-buffer rasterizer into a 2D canvas (as gegnn/render.py draws PNGs: a cloud's
// points as discs of about their spacing): no WebGL, no network, nothing but this file and the data the page
// carries.
"use strict";
(function () {
  const DATA = JSON.parse(document.getElementById("gegnn-data").textContent);

  // -- data -------------------------------------------------------------------------------------------
  function bytes(text) {
    const bin = atob(text);
    const out = new Uint8Array(bin.length);
    for (let i = 0; i < bin.length; i++) out[i] = bin.charCodeAt(i);
    return out.buffer;
  }
  function halfToFloat(h) {  // IEEE half (Uint16Array) -> Float32Array
    const out = new Float32Array(h.length);
    for (let i = 0; i < h.length; i++) {
      const s = h[i] & 0x8000 ? -1 : 1, e = (h[i] >> 10) & 0x1f, m = h[i] & 0x3ff;
      out[i] = e === 0 ? s * m * 2 ** -24 : e === 31 ? (m ? NaN : s * Infinity) : s * (1 + m / 1024) * 2 ** (e - 15);
    }
    return out;
  }
  function array(blob) {
    const buf = bytes(blob.data);
    if (blob.dtype === "float16") return halfToFloat(new Uint16Array(buf));
    return new { float32: Float32Array, uint32: Uint32Array, int32: Int32Array, uint8: Uint8Array }[blob.dtype](buf);
  }
  const CLOUD = !DATA.faces;  // a point cloud: no faces; its normals light its points
  const V = array(DATA.vertices), F = CLOUD ? new Uint32Array(0) : array(DATA.faces), CODES = array(DATA.codes);
  const NORMALS = CLOUD ? array(DATA.normals) : null;
  const COMPONENT = array(DATA.component), N = V.length / 3, NF = F.length / 3, C = DATA.code_width;
  const LABEL = DATA.file_index ? array(DATA.file_index) : null;  // mesh vertex -> the file's numbering
  const DECIMATED = !CLOUD && DATA.display;  // a decimated display: LABEL, the mesh's vertex nearest each
  const EXACT = {};
  for (const [src, blob] of Object.entries(DATA.exact || {})) EXACT[src] = array(blob);
  const LUTS = { viridis: array(DATA.luts.viridis), magma: array(DATA.luts.magma) };

  // -- the decoder (gegnn/decoders.py) ----------------------------------------------------------------
  const DEC = DATA.decoder;
  const LAYERS = (DEC.layers || []).map((l) => ({ w: array(l.weight), b: array(l.bias), n_in: l.n_in, n_out: l.n_out }));
  const WIDTH = Math.max(64, ...LAYERS.map((l) => Math.max(l.n_in, l.n_out)));
  const bufA = new Float64Array(WIDTH), bufB = new Float64Array(WIDTH);

  function mlp(x) {  // Linear-ReLU ... Linear, the value of the last layer
    let input = x, output = bufB;
    for (let l = 0; l < LAYERS.length; l++) {
      const { w, b, n_in, n_out } = LAYERS[l], last = l === LAYERS.length - 1;
      for (let o = 0; o < n_out; o++) {
        let acc = b[o];
        const row = o * n_in;
        for (let i = 0; i < n_in; i++) acc += w[row + i] * input[i];
        output[o] = last || acc > 0 ? acc : 0;
      }
      input = output;
      output = output === bufB ? bufA : bufB;
    }
    return input[0];
  }

  function embeddingDiff(a, b, d, x) {  // x[0:d] = (e_a - e_b)^2
    for (let i = 0; i < d; i++) { const t = CODES[a + i] - CODES[b + i]; x[i] = t * t; }
  }

  // Codes [e (D) | f (K) | n (1) | p (3)]: LandmarkDecoder.inputs and .output.
  function landmark(a, b, x) {
    const d = DEC.embed_dim, k = DEC.k, e = DEC.embedding ? d : 0;
    let upper = Infinity, lower = 0, sum = 0, sq = 0;
    for (let i = 0; i < k; i++) {
      const fa = CODES[a + d + i], fb = CODES[b + d + i], s = Math.abs(fa - fb);
      upper = Math.min(upper, fa + fb); lower = Math.max(lower, s); sum += s; sq += s * s;
    }
    const na = CODES[a + d + k], nb = CODES[b + d + k], u = Math.max(upper, 1e-6);
    if (DEC.embedding) embeddingDiff(a, b, d, x);
    let j = e;
    x[j++] = lower / u; x[j++] = sum / k / u; x[j++] = Math.sqrt(sq) / Math.sqrt(k) / u;
    x[j++] = (na + nb) / u; x[j++] = Math.abs(na - nb) / u;
    if (DEC.euclidean) {
      const p = d + k + 1;
      const dx = CODES[a + p] - CODES[b + p], dy = CODES[a + p + 1] - CODES[b + p + 1], dz = CODES[a + p + 2] - CODES[b + p + 2];
      x[j++] = Math.sqrt(dx * dx + dy * dy + dz * dz) / u;
    }
    x[j] = Math.log(u);
    if (!(lower > 0)) return 0;
    const t = mlp(x);
    if (DEC.output === "ratio") return lower * Math.exp(Math.min(t, DEC.max_log_ratio));
    return lower + Math.max(upper - lower, 0) / (1 + Math.exp(-t));
  }

  // Codes [e (D) | s (m) | tau (1) | p (3)]: SpectralDecoder.inputs and .output.
  const WEYL = DEC.weyl ? array(DEC.weyl) : null;
  function weylShape(s) {
    if (s >= DEC.s_max) return 1;
    const x = Math.sqrt(Math.max(s, 0) / DEC.s_max) * (WEYL.length - 1);
    const i = Math.min(Math.floor(x), WEYL.length - 2), t = x - i;
    return WEYL[i] + t * (WEYL[i + 1] - WEYL[i]);
  }
  function spectral(a, b, x) {
    const d = DEC.embed_dim, m = DEC.m, e = DEC.embedding ? d : 0;
    let bound = 0;
    for (let i = 0; i < m; i++) { const t = CODES[a + d + i] - CODES[b + d + i]; bound += t * t; }
    const tau = 0.5 * (CODES[a + d + m] + CODES[b + d + m]);
    let r2 = 0;
    for (let i = 1; i <= 3; i++) { const t = CODES[a + d + m + i] - CODES[b + d + m + i]; r2 += t * t; }
    const s = Math.sqrt(r2) / Math.sqrt(Math.max(2 * Math.PI * tau, 1e-30));
    const shape = weylShape(s), tail = tau * shape;
    if (DEC.embedding) embeddingDiff(a, b, d, x);
    x[e] = shape; x[e + 1] = bound / Math.max(bound + tail, 1e-30); x[e + 2] = Math.log(Math.max(s, 1e-6));
    return Math.sqrt(bound + tail * Math.exp(Math.min(mlp(x), DEC.max_log_ratio)));
  }

  // Codes [e (D)]: DistanceDecoder ("mlp": |MLP((e_a - e_b)^2)|, "euclidean": ||e_a - e_b||).
  function embeddingOnly(a, b, x) {
    embeddingDiff(a, b, C, x);
    if (!LAYERS.length) { let s = 0; for (let i = 0; i < C; i++) s += x[i]; return Math.sqrt(s); }
    return Math.abs(mlp(x));
  }

  const PAIR = { landmark, spectral, distance: embeddingOnly }[DEC.kind];
  const X = new Float64Array(WIDTH + 16);

  /** Distances from vertex ``src`` to every vertex, in the mesh's units (NaN off the source's part). */
  function decodeField(src) {
    const out = new Float32Array(N), a = src * C;
    for (let v = 0; v < N; v++) {
      out[v] = v === src ? 0 : COMPONENT[v] !== COMPONENT[src] ? NaN : PAIR(a, v * C, X) * DATA.scale;
    }
    return out;
  }

  // -- camera: turntable about the mesh's up axis ------------------------------------------------------
  const cam = DATA.camera;
  const UP = cam.up, H0 = cam.horizontal, H1 = cross(UP, H0);
  let yaw = 0, pitch = cam.elevation, zoom = 1, panX = 0, panY = 0;
  function cross(a, b) { return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]; }
  function normalize(a) { const n = Math.hypot(a[0], a[1], a[2]); return [a[0] / n, a[1] / n, a[2] / n]; }
  function rotation() {  // rows: screen right, screen up, towards the viewer (as gegnn.pictures.render.View)
    const cy = Math.cos(yaw), sy = Math.sin(yaw), cp = Math.cos(pitch), sp = Math.sin(pitch);
    const toward = [0, 1, 2].map((i) => cp * (cy * H0[i] + sy * H1[i]) + sp * UP[i]);
    const right = normalize(cross(UP, toward));
    return [right, cross(toward, right), toward];
  }
  const RADIUS = (() => {
    let r = 0;
    for (let v = 0; v < N; v++) {
      r = Math.max(r, Math.hypot(V[3 * v] - cam.center[0], V[3 * v + 1] - cam.center[1], V[3 * v + 2] - cam.center[2]));
    }
    return r || 1;
  })();

  // -- rasterizer --------------------------------------------------------------------------------------
  const canvas = document.getElementById("gegnn-canvas"), ctx = canvas.getContext("2d");
  let W = 0, H = 0, image, zbuf, fbuf, vbuf, light;
  const SX = new Float32Array(N), SY = new Float32Array(N), SZ = new Float32Array(N);
  const faceLight = new Float32Array(NF);

  function resize() {
    const box = canvas.parentElement.getBoundingClientRect();
    W = Math.max(64, Math.floor(box.width)); H = Math.max(64, Math.floor(box.height));
    canvas.width = W; canvas.height = H;
    image = ctx.createImageData(W, H);
    zbuf = new Float32Array(W * H); fbuf = new Int32Array(W * H); vbuf = new Float32Array(W * H);
    light = new Float32Array(W * H);
    draw();
  }

  function pixelsPerUnit() { return zoom * 0.47 * Math.min(W, H) / RADIUS; }
  function projectAll(R) {
    const s = pixelsPerUnit(), [c0, c1, c2] = cam.center;
    for (let v = 0; v < N; v++) {
      const x = V[3 * v] - c0, y = V[3 * v + 1] - c1, z = V[3 * v + 2] - c2;
      SX[v] = W / 2 + panX + s * (R[0][0] * x + R[0][1] * y + R[0][2] * z);
      SY[v] = H / 2 + panY - s * (R[1][0] * x + R[1][1] * y + R[1][2] * z);
      SZ[v] = R[2][0] * x + R[2][1] * y + R[2][2] * z;
    }
  }

  function rasterize(R, values) {
    projectAll(R);
    zbuf.fill(-Infinity); fbuf.fill(-1);
    if (CLOUD) { splat(R, values); return; }
    const t = R[2];
    for (let f = 0; f < NF; f++) {
      const a = F[3 * f], b = F[3 * f + 1], c = F[3 * f + 2];
      const ax = SX[a], ay = SY[a], bx = SX[b], by = SY[b], cx = SX[c], cy = SY[c];
      const area = (bx - ax) * (cy - ay) - (by - ay) * (cx - ax);
      if (Math.abs(area) < 1e-12) continue;
      // Lambert shading by the face normal, both sides lit (as render.shade_field)
      const ux = V[3 * b] - V[3 * a], uy = V[3 * b + 1] - V[3 * a + 1], uz = V[3 * b + 2] - V[3 * a + 2];
      const wx = V[3 * c] - V[3 * a], wy = V[3 * c + 1] - V[3 * a + 1], wz = V[3 * c + 2] - V[3 * a + 2];
      const nx = uy * wz - uz * wy, ny = uz * wx - ux * wz, nz = ux * wy - uy * wx;
      faceLight[f] = 0.45 + 0.55 * Math.abs(nx * t[0] + ny * t[1] + nz * t[2]) / (Math.hypot(nx, ny, nz) || 1);
      const x0 = Math.max(0, Math.floor(Math.min(ax, bx, cx))), x1 = Math.min(W - 1, Math.ceil(Math.max(ax, bx, cx)));
      const y0 = Math.max(0, Math.floor(Math.min(ay, by, cy))), y1 = Math.min(H - 1, Math.ceil(Math.max(ay, by, cy)));
      const za = SZ[a], zb = SZ[b], zc = SZ[c], va = values[a], vb = values[b], vc = values[c];
      for (let y = y0; y <= y1; y++) {
        const py = y + 0.5;
        for (let x = x0; x <= x1; x++) {
          const px = x + 0.5;
          const l0 = ((bx - px) * (cy - py) - (by - py) * (cx - px)) / area;
          const l1 = ((cx - px) * (ay - py) - (cy - py) * (ax - px)) / area;
          const l2 = 1 - l0 - l1;
          if (l0 < -1e-9 || l1 < -1e-9 || l2 < -1e-9) continue;
          const z = l0 * za + l1 * zb + l2 * zc, i = y * W + x;
          if (z <= zbuf[i]) continue;
          zbuf[i] = z; fbuf[i] = f; light[i] = faceLight[f];
          vbuf[i] = l0 * va + l1 * vb + l2 * vc;
        }
      }
    }
  }

  function splat(R, values) {  // a cloud: every point a disc, the nearest in front; fbuf holds the point
    const r = Math.max(1, DATA.point_radius * pixelsPerUnit()), reach = Math.ceil(r), t = R[2];
    for (let v = 0; v < N; v++) {
      const lit = 0.45 + 0.55 * Math.abs(NORMALS[3 * v] * t[0] + NORMALS[3 * v + 1] * t[1] + NORMALS[3 * v + 2] * t[2]);
      const cx = Math.floor(SX[v]), cy = Math.floor(SY[v]), z = SZ[v], value = values[v];
      for (let dy = -reach; dy <= reach; dy++) {
        const y = cy + dy;
        if (y < 0 || y >= H) continue;
        for (let dx = -reach; dx <= reach; dx++) {
          const x = cx + dx, i = y * W + x;
          if (x < 0 || x >= W || dx * dx + dy * dy > r * r || z <= zbuf[i]) continue;
          zbuf[i] = z; fbuf[i] = v; light[i] = lit; vbuf[i] = value;
        }
      }
    }
  }

  const ISOLINES = 12;
  function shade(lut, vmin, vmax, isolines) {
    const px = image.data, span = Math.max(vmax - vmin, 1e-30), band = new Float32Array(W * H);
    for (let i = 0; i < W * H; i++) {
      const o = 4 * i;
      if (fbuf[i] < 0) { px[o] = px[o + 1] = px[o + 2] = 255; px[o + 3] = 255; band[i] = NaN; continue; }
      const value = vbuf[i];
      let r, g, b;
      if (Number.isNaN(value)) { r = g = b = 0.62; band[i] = NaN; } else {
        const t = Math.min(1, Math.max(0, (value - vmin) / span)), k = 3 * Math.round(t * 255);
        r = lut[k]; g = lut[k + 1]; b = lut[k + 2];
        band[i] = Math.floor(t * isolines - 1e-9);
      }
      px[o] = 255 * r * light[i]; px[o + 1] = 255 * g * light[i]; px[o + 2] = 255 * b * light[i]; px[o + 3] = 255;
    }
    if (!isolines) return;
    for (let y = 0; y < H; y++) {
      for (let x = 0; x < W; x++) {
        const i = y * W + x, here = band[i];
        if (Number.isNaN(here)) continue;
        const right = x + 1 < W ? band[i + 1] : here, down = y + 1 < H ? band[i + W] : here;
        if ((!Number.isNaN(right) && right !== here) || (!Number.isNaN(down) && down !== here)) {
          const o = 4 * i;
          px[o] *= 0.25; px[o + 1] *= 0.25; px[o + 2] *= 0.25;
        }
      }
    }
  }

  // -- state and drawing -------------------------------------------------------------------------------
  const state = { source: DATA.sources[0], mode: "predicted", predicted: null, exact: null, decodeMs: 0, frames: 0 };

  function shown() {  // the values drawn, their colormap and range
    const top = state.exact ? max(state.exact) : max(state.predicted);
    if (state.mode === "exact" && state.exact) return [state.exact, LUTS.viridis, 0, top, ISOLINES];
    if (state.mode === "error" && state.exact) return [relativeError(), LUTS.magma, 0, 0.1, 0];
    return [state.predicted, LUTS.viridis, 0, top, ISOLINES];
  }
  function max(a) { let m = 0; for (const x of a) if (x > m) m = x; return m; }
  function relativeError() {  // |pred - exact| / (exact + offset): gegnn.queries.files.relative_errors, 0 at the source
    const out = new Float32Array(N), p = state.predicted, e = state.exact;
    for (let v = 0; v < N; v++) out[v] = Math.abs(p[v] - e[v]) / (e[v] + DATA.metric_offset);
    out[state.source] = 0;
    return out;
  }

  let pending = false;
  function draw() {
    if (pending || !W) return;
    pending = true;
    requestAnimationFrame(() => {
      pending = false;
      const t0 = performance.now();
      const [values, lut, vmin, vmax, isolines] = shown();
      const R = rotation();
      rasterize(R, values);
      shade(lut, vmin, vmax, isolines);
      ctx.putImageData(image, 0, 0);
      marker(state.source);
      colorbar(lut, vmin, vmax);
      state.frames++;
      document.body.dataset.frames = state.frames;
      document.body.dataset.frameMs = (performance.now() - t0).toFixed(1);
      if (pointer) showCursor(pointer[0], pointer[1]);
    });
  }

  function marker(v) {  // a red dot on the source, where it is not hidden
    const x = Math.floor(SX[v]), y = Math.floor(SY[v]);
    if (x < 0 || y < 0 || x >= W || y >= H) return;
    if (SZ[v] < zbuf[y * W + x] - 0.04 * RADIUS) return;  // 2% of the depth range, as render.py
    ctx.fillStyle = "#d91a1a";
    ctx.beginPath(); ctx.arc(SX[v], SY[v], Math.max(3, Math.min(W, H) / 150), 0, 2 * Math.PI); ctx.fill();
  }

  // -- the panel ---------------------------------------------------------------------------------------
  const $ = (id) => document.getElementById(id);
  function label(v) {
    const what = CLOUD ? "point" : "vertex";
    if (DECIMATED) return `near vertex ${LABEL[v]}${DECIMATED.numbering === "mesh" ? " (of the remeshed mesh)" : ""}`;
    return LABEL ? `${what} ${LABEL[v]}` : `${what} ${v}${CLOUD ? "" : " (of the remeshed mesh)"}`;
  }
  function fmt(x) { return Number.isNaN(x) ? "no distance (another part)" : x.toPrecision(4); }

  function colorbar(lut, vmin, vmax) {
    const bar = $("gegnn-bar"), g = bar.getContext("2d"), w = bar.width, h = bar.height;
    for (let x = 0; x < w; x++) {
      const k = 3 * Math.round((x / (w - 1)) * 255);
      g.fillStyle = `rgb(${255 * lut[k]},${255 * lut[k + 1]},${255 * lut[k + 2]})`;
      g.fillRect(x, 0, 1, h);
    }
    $("gegnn-bar-lo").textContent = vmin.toPrecision(3);
    $("gegnn-bar-hi").textContent = state.mode === "error" ? "10%" : vmax.toPrecision(4);
    $("gegnn-bar-label").textContent = state.mode === "error" ? "|predicted - exact| / exact" : "distance";
  }

  function setSource(v) {
    const t0 = performance.now();
    state.source = v;
    state.predicted = decodeField(v);
    state.decodeMs = performance.now() - t0;
    state.exact = EXACT[v] || null;
    if (!state.exact && state.mode !== "predicted") state.mode = "predicted";
    for (const input of document.querySelectorAll("input[name=gegnn-mode]")) {
      input.disabled = input.value !== "predicted" && !state.exact;
      input.checked = input.value === state.mode;
    }
    let text = `source: ${label(v)} · decoded ${N.toLocaleString()} distances in the page in ${state.decodeMs.toFixed(0)} ms`;
    if (state.exact) {
      let sum = 0, count = 0;
      const err = relativeError();
      for (let u = 0; u < N; u++) if (u !== v && !Number.isNaN(err[u])) { sum += err[u]; count++; }  // NaN: other parts
      text += ` · mean relative error vs exact ${(100 * sum / Math.max(count, 1)).toFixed(2)}%`;
    }
    $("gegnn-source").textContent = text;
    document.body.dataset.source = v;
    document.body.dataset.decodeMs = state.decodeMs.toFixed(1);
    draw();
  }

  function pick(clientX, clientY) {  // the vertex of the drawn face nearest the pixel (a cloud's drawn point), or -1
    const box = canvas.getBoundingClientRect(), x = Math.floor(clientX - box.left), y = Math.floor(clientY - box.top);
    if (x < 0 || y < 0 || x >= W || y >= H) return [-1, NaN];
    const f = fbuf[y * W + x];
    if (f < 0) return [-1, NaN];
    if (CLOUD) return [f, vbuf[y * W + x]];
    let best = -1, bestD = Infinity;
    for (let k = 0; k < 3; k++) {
      const v = F[3 * f + k], d = Math.hypot(SX[v] - x - 0.5, SY[v] - y - 0.5);
      if (d < bestD) { bestD = d; best = v; }
    }
    return [best, vbuf[y * W + x]];
  }

  function showCursor(x, y) {  // the value drawn under the pointer
    const [v, value] = pick(x, y), error = state.mode === "error";
    $("gegnn-cursor").textContent = v < 0 ? "" : `under the cursor: ${DECIMATED ? "" : "near "}${label(v)}, ` +
      (error ? `relative error ${(100 * value).toFixed(2)}%` : `${state.mode} distance ${fmt(value)}`);
  }

  // -- interaction -------------------------------------------------------------------------------------
  let drag = null, pointer = null;
  canvas.addEventListener("pointerdown", (e) => {
    drag = { x: e.clientX, y: e.clientY, moved: 0, pan: e.shiftKey || e.button === 2 };
    canvas.setPointerCapture(e.pointerId);
  });
  canvas.addEventListener("pointermove", (e) => {
    if (drag) {
      const dx = e.clientX - drag.x, dy = e.clientY - drag.y;
      drag.moved += Math.abs(dx) + Math.abs(dy);
      drag.x = e.clientX; drag.y = e.clientY;
      if (drag.pan) { panX += dx; panY += dy; } else {
        yaw -= dx * 0.01;
        pitch = Math.max(-1.55, Math.min(1.55, pitch + dy * 0.01));
      }
      draw();
      return;
    }
    pointer = [e.clientX, e.clientY];
    showCursor(e.clientX, e.clientY);
  });
  canvas.addEventListener("pointerleave", () => { pointer = null; $("gegnn-cursor").textContent = ""; });
  canvas.addEventListener("pointerup", (e) => {
    const click = drag && drag.moved < 4 && !drag.pan;
    drag = null;
    if (!click) return;
    const [v] = pick(e.clientX, e.clientY);
    if (v >= 0) setSource(v);
  });
  canvas.addEventListener("contextmenu", (e) => e.preventDefault());
  canvas.addEventListener("wheel", (e) => {
    e.preventDefault();
    zoom *= Math.exp(-e.deltaY * 0.0015);
    draw();
  }, { passive: false });
  for (const input of document.querySelectorAll("input[name=gegnn-mode]")) {
    input.addEventListener("change", () => { state.mode = input.value; draw(); });
  }
  $("gegnn-reset").addEventListener("click", () => { yaw = 0; pitch = cam.elevation; zoom = 1; panX = panY = 0; draw(); });
  const list = $("gegnn-exact-sources");
  for (const src of Object.keys(EXACT)) {
    const button = document.createElement("button");
    button.textContent = label(Number(src));
    button.addEventListener("click", () => setSource(Number(src)));
    list.appendChild(button);
  }
  if (!list.children.length) list.parentElement.hidden = true;
  new ResizeObserver(resize).observe(canvas.parentElement);

  // For scripts and tests: the page's own decoder and camera.
  window.gegnn = {
    field: (v) => Array.from(decodeField(v)),
    setSource,
    source: () => state.source,
    screen: (v) => { const box = canvas.getBoundingClientRect(); return [box.left + SX[v], box.top + SY[v]]; },
    pick: (x, y) => pick(x, y)[0],
    shown: () => Array.from(shown()[0]),
  };
  setSource(state.source);
  resize();
})();
