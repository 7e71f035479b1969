// slamrel scan relation review: canvases, no library, no network (see slamrel/review/scans.py).
// State: one entry per proposed relation with a status (unreviewed, accepted, rejected) and the
// relation shown; every change is one undoable action. Save writes a Freiburg .relations file
// of the accepted relations (headed by the counts) and the review state.
"use strict";
(function () {
  const DATA = JSON.parse(document.getElementById("review-data").textContent);
  const R = DATA.relations, SCANS = DATA.scans, ICP = DATA.icp;
  const WIN = DATA.window || { xy: 0.1, theta: Math.PI / 180 };
  const $ = (id) => document.getElementById(id);
  const canvas = $("map"), ctx = canvas.getContext("2d");
  const inset = $("inset"), ictx = inset.getContext("2d");
  const prof = $("profile"), pctx = prof.getContext("2d");
  const DEG = Math.PI / 180, STATES = ["unreviewed", "accepted", "rejected"];
  const triple = (a, k) => (a && a[3 * k] !== null && a[3 * k] !== undefined ? a.slice(3 * k, 3 * k + 3) : null);

  const rels = R.t1.map((t1, k) => ({
    t1, t2: R.t2[k], i: R.i[k], j: R.j[k],
    proposed: R.delta.slice(3 * k, 3 * k + 3), delta: R.delta.slice(3 * k, 3 * k + 3),
    estimate: triple(R.estimate, k), second: triple(R.second, k),
    secondRatio: R.secondRatio ? R.secondRatio[k] : null,
    weak: R.weak && R.weak[2 * k] !== null ? [R.weak[2 * k], R.weak[2 * k + 1]] : null,
    matched: R.matched[k], residual: R.residual[k], condition: R.condition[k],
    flags: R.flags[k], suspicion: R.suspicion[k] ?? Infinity,
    status: "unreviewed", edited: false,
  }));
  const undoStack = [];
  let selected = -1, showMap = true, lastWindow = null;
  const view = { cx: 0, cy: 0, scale: 40 };

  function say(text) { $("status").textContent = text; }
  const wrap = (a) => Math.atan2(Math.sin(a), Math.cos(a));

  // ------------------------------------------------------------------- the map
  // cells: base64 of little-endian uint16 pairs relative to origin; a cell's centre in metres
  const MAP = (() => {
    const m = DATA.map;
    if (!m || !m.count) return new Float64Array(0);
    const bin = atob(m.cells), dv = new DataView(new ArrayBuffer(bin.length));
    for (let k = 0; k < bin.length; k++) dv.setUint8(k, bin.charCodeAt(k));
    const out = new Float64Array(2 * m.count);
    for (let k = 0; k < 2 * m.count; k++) out[k] = (m.origin[k % 2] + dv.getUint16(2 * k, true) + 0.5) * m.resolution;
    return out;
  })();
  const local = { i: -1, pts: null };
  function mapInFrame(i) { // the map in the frame of used scan i (the reference frame)
    if (local.i === i) return local.pts;
    const P = DATA.poses, x = P[3 * i], y = P[3 * i + 1], c = Math.cos(P[3 * i + 2]), s = Math.sin(P[3 * i + 2]);
    const out = new Float32Array(MAP.length);
    for (let m = 0; m < MAP.length; m += 2) {
      const dx = MAP[m] - x, dy = MAP[m + 1] - y;
      out[m] = c * dx + s * dy; out[m + 1] = -s * dx + c * dy;
    }
    local.i = i; local.pts = out;
    return out;
  }

  // ------------------------------------------------------------------- changes and undo
  function snapshot(k) { const r = rels[k]; return { status: r.status, delta: r.delta.slice(), edited: r.edited }; }
  function change(k, after) {
    const before = snapshot(k);
    const last = undoStack[undoStack.length - 1];
    // consecutive nudges of one relation are one action
    if (!(after.nudge && last && last.k === k && last.nudge)) undoStack.push({ k, before, nudge: !!after.nudge });
    Object.assign(rels[k], { status: after.status ?? rels[k].status,
      delta: after.delta ?? rels[k].delta, edited: after.edited ?? rels[k].edited });
    refresh();
  }
  function undo() {
    const act = undoStack.pop();
    if (!act) { say("nothing to undo"); return; }
    Object.assign(rels[act.k], act.before);
    selected = act.k;
    say("undone");
    refresh();
  }
  function nudge(dx, dy, dth) {
    if (selected < 0) { say("select a relation first (n)"); return; }
    const d = rels[selected].delta;
    change(selected, { delta: [d[0] + dx, d[1] + dy, wrap(d[2] + dth)], edited: true, nudge: true });
  }
  function toSecond() {
    if (selected < 0) { say("select a relation first (n)"); return; }
    const s = rels[selected].second;
    if (!s) { say("this relation has no second hypothesis"); return; }
    change(selected, { delta: s.slice(), edited: true });
    say("moved to the second hypothesis");
  }

  // ------------------------------------------------------------------- navigation
  function order() {
    const idx = [];
    rels.forEach((r, k) => { if (r.status === "unreviewed") idx.push(k); });
    return idx.sort((a, b) => rels[b].suspicion - rels[a].suspicion || a - b);
  }
  function step(dir) {
    const o = order();
    if (!o.length) { say("no unreviewed relation left"); return; }
    let pos = o.indexOf(selected);
    pos = pos < 0 ? (dir > 0 ? 0 : o.length - 1) : (pos + dir + o.length) % o.length;
    select(o[pos]);
  }
  function decide(status) {
    if (selected < 0) { say("select a relation first (n)"); return; }
    change(selected, { status });
    const o = order();
    if (o.length) select(o[0]);
  }
  function select(k) { selected = k; lastWindow = null; fit(); refresh(); }

  // ------------------------------------------------------------------- geometry
  function moved(scan, d) {
    const c = Math.cos(d[2]), s = Math.sin(d[2]), p = scan.p, out = new Float64Array(p.length);
    for (let m = 0; m < p.length; m += 2) {
      out[m] = c * p[m] - s * p[m + 1] + d[0];
      out[m + 1] = s * p[m] + c * p[m + 1] + d[1];
    }
    return out;
  }
  // the reference lines hashed on cells of ICP.maxDistance: the nearest centroid within a gate
  // no larger than a cell lies in the 3 x 3 cells around a point (the same answer as a search
  // over every line)
  const cellKey = (ix, iy) => (ix + 1048576) * 2097152 + (iy + 1048576);
  function lineHash(ref) {
    if (ref.hash) return ref.hash;
    const h = new Map(), c = ICP.maxDistance;
    for (let l = 0; l < ref.c.length / 2; l++) {
      const key = cellKey(Math.floor(ref.c[2 * l] / c), Math.floor(ref.c[2 * l + 1] / c));
      if (!h.has(key)) h.set(key, []);
      h.get(key).push(l);
    }
    ref.hash = h;
    return h;
  }
  function nearestLine(ref, h, x, y, gate) {
    const c = ICP.maxDistance, ix = Math.floor(x / c), iy = Math.floor(y / c);
    let best = gate * gate, b = -1;
    for (let a = -1; a <= 1; a++) for (let q = -1; q <= 1; q++) {
      const list = h.get(cellKey(ix + a, iy + q));
      if (!list) continue;
      for (const l of list) {
        const dx = x - ref.c[2 * l], dy = y - ref.c[2 * l + 1], d2 = dx * dx + dy * dy;
        if (d2 < best || (d2 === best && l < b)) { best = d2; b = l; }
      }
    }
    return b;
  }
  // Point-to-line ICP, as slamrel.scans.matching.align: nearest line centroid within the gate,
  // trimmed share, Cauchy weights on the robust scale, Gauss-Newton on [tx, ty, theta]. With a
  // box {lo, hi} every step is held inside it (a trust region: the window of re-align).
  function icp(ref, cur, x0, box) {
    const x = x0.slice(), h = lineHash(ref);
    let gate = ICP.maxDistance, sigma = ICP.minSigma, converged = false, it = 0, matched = 0, rms = NaN;
    let stalled = 0;
    const history = [x.slice()];
    // period p <= 4 with x_k = x_{k-p} seen twice: the correspondences repeat
    const cycle = () => {
      for (let p = 2; p <= 4; p++) {
        if (history.length <= 2 * p) continue;
        let same = true;
        for (let q = 0; q < p && same; q++) {
          const a = history[history.length - 1 - q], b = history[history.length - 1 - q - p];
          same = Math.max(...a.map((v, k) => Math.abs(v - b[k]))) < ICP.tolerance;
        }
        if (same) return p;
      }
      return 0;
    };
    for (it = 1; it <= ICP.maxIterations; it++) {
      const q = moved(cur, x), res = [];
      for (let m = 0; m < q.length; m += 2) {
        const b = nearestLine(ref, h, q[m], q[m + 1], gate);
        if (b >= 0) {
          const nx = ref.n[2 * b], ny = ref.n[2 * b + 1];
          const e = nx * (q[m] - ref.c[2 * b]) + ny * (q[m + 1] - ref.c[2 * b + 1]);
          res.push([e, nx, ny, q[m] - x[0], q[m + 1] - x[1]]);
        }
      }
      if (res.length < ICP.minMatches) return { delta: x0.slice(), ok: false, matched: 0, rms: NaN };
      res.sort((a, b) => Math.abs(a[0]) - Math.abs(b[0]));
      const keep = Math.max(ICP.minMatches, Math.ceil(ICP.trim * res.length));
      const use = res.slice(0, keep), abs = use.map((r) => Math.abs(r[0]));
      sigma = Math.max(1.4826 * abs[Math.floor((abs.length - 1) / 2)], ICP.minSigma);
      const H = [[0, 0, 0], [0, 0, 0], [0, 0, 0]], g = [0, 0, 0];
      let s2 = 0;
      for (const [e, nx, ny, rx, ry] of use) {
        const w = 1 / (1 + (e / (2.385 * sigma)) ** 2), J = [nx, ny, ny * rx - nx * ry];
        for (let a = 0; a < 3; a++) { g[a] += w * J[a] * e; for (let b = 0; b < 3; b++) H[a][b] += w * J[a] * J[b]; }
        s2 += e * e;
      }
      const dxv = solve3(H, g);
      if (!dxv) break;
      const prev = x.slice();
      for (let k = 0; k < 3; k++) {
        x[k] -= dxv[k];
        if (box) x[k] = Math.min(box.hi[k], Math.max(box.lo[k], x[k]));
        dxv[k] = prev[k] - x[k];
      }
      history.push(x.slice());
      matched = use.filter((r) => Math.abs(r[0]) <= 3 * sigma).length;
      rms = Math.sqrt(s2 / use.length);
      const newGate = Math.min(ICP.maxDistance, Math.max(ICP.minDistance, ICP.gateSigmas * sigma));
      const size = Math.max(Math.hypot(dxv[0], dxv[1]), Math.abs(dxv[2]));
      const small = size < ICP.tolerance, settled = newGate >= gate * 0.999;
      stalled = size < ICP.stallTolerance ? stalled + 1 : 0;
      if ((small || stalled >= ICP.stallIterations) && settled) { converged = true; break; }
      const period = cycle();
      if (period && settled) {
        const last = history.slice(-period);
        for (let k = 0; k < 3; k++) x[k] = last.reduce((acc, v) => acc + v[k], 0) / period;
        converged = true;
        break;
      }
      if (small || it > 5) gate = Math.min(gate, newGate);
    }
    x[2] = wrap(x[2]);
    return { delta: x, ok: true, converged, iterations: it, matched: matched / (cur.p.length / 2), rms };
  }
  function solve3(A, b) {
    const m = A.map((row, r) => row.concat([b[r]]));
    for (let c = 0; c < 3; c++) {
      let p = c;
      for (let r = c + 1; r < 3; r++) if (Math.abs(m[r][c]) > Math.abs(m[p][c])) p = r;
      if (Math.abs(m[p][c]) < 1e-15) return null;
      [m[c], m[p]] = [m[p], m[c]];
      for (let r = 0; r < 3; r++) if (r !== c) {
        const f = m[r][c] / m[c][c];
        for (let k = c; k < 4; k++) m[r][k] -= f * m[c][k];
      }
    }
    return [m[0][3] / m[0][0], m[1][3] / m[1][1], m[2][3] / m[2][2]];
  }
  // ------------------------------------------------------------------- windowed re-align
  // A correlative search (Olson 2009) over the window: the reference scan rasterised on 2 cm
  // cells, each cell scored exp(-d^2 / 2 sigma^2) (sigma 2 cm) by its distance d to the
  // reference returns (neighbours along the scan joined by 2 cm steps), the current scan's
  // returns summed over the raster for every (dx, dy) on 2 cm steps and theta on 0.2 deg steps
  // within the window; then the ICP from the best candidate, held inside the window (the ICP
  // gives the precision, the search the basin).
  const RCELL = 0.02, RSIG = 0.02, RRAD = 3, RTHETA = 0.2 * DEG;
  function raster(ref) {
    if (ref.raster) return ref.raster;
    const h = new Map(), p = ref.p;
    const stamp = (x, y) => {
      const ix = Math.round(x / RCELL), iy = Math.round(y / RCELL);
      for (let a = -RRAD; a <= RRAD; a++) for (let b = -RRAD; b <= RRAD; b++) {
        const dx = (ix + a) * RCELL - x, dy = (iy + b) * RCELL - y;
        const v = Math.exp(-(dx * dx + dy * dy) / (2 * RSIG * RSIG)), key = cellKey(ix + a, iy + b);
        if (v > (h.get(key) ?? 0)) h.set(key, v);
      }
    };
    for (let m = 0; m < p.length; m += 2) {
      stamp(p[m], p[m + 1]);
      if (m + 3 >= p.length) continue;
      const gap = Math.hypot(p[m + 2] - p[m], p[m + 3] - p[m + 1]);
      if (gap > Math.max(0.3, 0.03 * Math.hypot(p[m], p[m + 1]))) continue;
      const n = Math.ceil(gap / RCELL);
      for (let s = 1; s < n; s++) stamp(p[m] + (p[m + 2] - p[m]) * s / n, p[m + 1] + (p[m + 3] - p[m + 1]) * s / n);
    }
    ref.raster = h;
    return h;
  }
  function windowSearch(ref, cur, x0) {
    const h = raster(ref), nxy = Math.round(WIN.xy / RCELL), nth = Math.round(WIN.theta / RTHETA);
    let best = { score: -1, d: x0.slice(), dist: Infinity };
    const m = cur.p.length / 2, ix = new Int32Array(m), iy = new Int32Array(m);
    for (let t = -nth; t <= nth; t++) {
      const th = x0[2] + t * RTHETA, c = Math.cos(th), s = Math.sin(th);
      for (let k = 0; k < m; k++) {
        const px = cur.p[2 * k], py = cur.p[2 * k + 1];
        ix[k] = Math.round((c * px - s * py + x0[0]) / RCELL); iy[k] = Math.round((s * px + c * py + x0[1]) / RCELL);
      }
      for (let a = -nxy; a <= nxy; a++) for (let b = -nxy; b <= nxy; b++) {
        let score = 0;
        for (let k = 0; k < m; k++) score += h.get(cellKey(ix[k] + a, iy[k] + b)) ?? 0;
        const dist = a * a + b * b + t * t;
        if (score > best.score + 1e-9 || (Math.abs(score - best.score) <= 1e-9 && dist < best.dist)) {
          best = { score, dist, d: [x0[0] + a * RCELL, x0[1] + b * RCELL, th] };
        }
      }
    }
    return best;
  }
  function windowed(k, x0) {
    const r = rels[k];
    const box = { lo: [x0[0] - WIN.xy, x0[1] - WIN.xy, x0[2] - WIN.theta], hi: [x0[0] + WIN.xy, x0[1] + WIN.xy, x0[2] + WIN.theta] };
    const c = windowSearch(SCANS[r.i], SCANS[r.j], x0);
    return icp(SCANS[r.i], SCANS[r.j], c.d, box);
  }
  function realignWindow() {
    if (selected < 0) { say("select a relation first (n)"); return; }
    const r = rels[selected], t0 = performance.now(), x0 = r.delta.slice();
    const out = windowed(selected, x0);
    if (!out.ok) { say("re-align failed: too few matches in the window"); return; }
    lastWindow = { k: selected, x0 };
    change(selected, { delta: out.delta, edited: true });
    say(`re-aligned within ±${(100 * WIN.xy).toFixed(0)} cm / ±${(WIN.theta / DEG).toFixed(1)}° in ` +
      `${(performance.now() - t0).toFixed(0)} ms: matched ${(100 * out.matched).toFixed(0)}%, ` +
      `residual ${(100 * out.rms).toFixed(1)} cm${out.converged ? "" : " (not converged)"}`);
  }
  function realignFree() {
    if (selected < 0) { say("select a relation first (n)"); return; }
    const r = rels[selected], t0 = performance.now();
    const out = icp(SCANS[r.i], SCANS[r.j], r.delta, null);
    if (!out.ok) { say("re-align failed: too few matches from here"); return; }
    lastWindow = null;
    change(selected, { delta: out.delta, edited: true });
    say(`re-aligned freely in ${(performance.now() - t0).toFixed(0)} ms: matched ${(100 * out.matched).toFixed(0)}%, ` +
      `residual ${(100 * out.rms).toFixed(1)} cm${out.converged ? "" : " (not converged)"}`);
  }
  // ------------------------------------------------------------------- cost along the weak direction
  // the trimmed point-to-line cost mean(min(e^2, tau^2)) (tau 10 cm; unmatched points tau^2) of
  // the current scan shifted by s along the weak direction, s in [-2, 2] m on 2.5 cm steps
  const PROFILE = { half: 2, step: 0.025, tau: 0.1 };
  function weakOf(r) {
    const w = r.weak;
    return w && Number.isFinite(w[0]) && Number.isFinite(w[1]) && Math.hypot(w[0], w[1]) > 0.5 ? w : [1, 0];
  }
  function profile(k) {
    const r = rels[k], ref = SCANS[r.i], h = lineHash(ref), w = weakOf(r), q = moved(SCANS[r.j], r.delta);
    const n = Math.round(PROFILE.half / PROFILE.step), tau2 = PROFILE.tau ** 2;
    const stride = Math.max(1, Math.floor(q.length / 2 / 200)), cost = [];
    for (let a = -n; a <= n; a++) {
      const s = a * PROFILE.step;
      let sum = 0, cnt = 0;
      for (let m = 0; m < q.length; m += 2 * stride) {
        const x = q[m] + s * w[0], y = q[m + 1] + s * w[1], b = nearestLine(ref, h, x, y, ICP.maxDistance);
        let e2 = tau2;
        if (b >= 0) { const e = ref.n[2 * b] * (x - ref.c[2 * b]) + ref.n[2 * b + 1] * (y - ref.c[2 * b + 1]); e2 = Math.min(e * e, tau2); }
        sum += e2; cnt++;
      }
      cost.push([s, Math.sqrt(sum / Math.max(cnt, 1))]);
    }
    return { weak: w, cost };
  }
  function drawProfile() {
    const w = prof.clientWidth, hgt = prof.clientHeight, dpr = window.devicePixelRatio || 1;
    prof.width = Math.round(w * dpr); prof.height = Math.round(hgt * dpr);
    pctx.setTransform(dpr, 0, 0, dpr, 0, 0);
    pctx.clearRect(0, 0, w, hgt);
    pctx.fillStyle = "#333"; pctx.font = "11px system-ui, sans-serif";
    if (selected < 0) { pctx.fillText("cost along the weak direction", 6, 14); return; }
    const r = rels[selected], p = profile(selected), top = Math.max(...p.cost.map((c) => c[1]), 1e-6);
    const X = (s) => 6 + (s + PROFILE.half) / (2 * PROFILE.half) * (w - 12), Y = (v) => hgt - 16 - v / top * (hgt - 34);
    pctx.fillText(`RMS cost [cm] along the weak direction (${p.weak[0].toFixed(2)}, ${p.weak[1].toFixed(2)})`, 6, 12);
    const mark = (d, colour) => {
      if (!d) return;
      const s = (d[0] - r.delta[0]) * p.weak[0] + (d[1] - r.delta[1]) * p.weak[1];
      if (Math.abs(s) > PROFILE.half) return;
      pctx.strokeStyle = colour; pctx.lineWidth = 2; pctx.beginPath(); pctx.moveTo(X(s), 16); pctx.lineTo(X(s), hgt - 14); pctx.stroke();
    };
    mark(r.delta, "#e8710a"); mark(r.estimate, "#555"); mark(r.second, "#8e44ad");
    pctx.strokeStyle = "#1f5fbf"; pctx.lineWidth = 1.5; pctx.beginPath();
    p.cost.forEach(([s, v], a) => (a ? pctx.lineTo(X(s), Y(v)) : pctx.moveTo(X(s), Y(v))));
    pctx.stroke();
    pctx.fillStyle = "#333";
    pctx.fillText(`-${PROFILE.half} m`, 4, hgt - 3); pctx.fillText(`+${PROFILE.half} m`, w - 34, hgt - 3);
    pctx.fillText(`max ${(100 * top).toFixed(1)}`, w - 52, 26);
  }

  // ------------------------------------------------------------------- drawing
  function size() {
    const r = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    if (canvas.width !== Math.round(r.width * dpr) || canvas.height !== Math.round(r.height * dpr)) {
      canvas.width = Math.round(r.width * dpr); canvas.height = Math.round(r.height * dpr);
    }
    return { w: r.width, h: r.height, dpr };
  }
  const toScreen = (x, y, s) => [s.w / 2 + (x - view.cx) * view.scale, s.h / 2 - (y - view.cy) * view.scale];
  // both poses of the relation, the estimate's pose of the current scan and the reference
  // scan's returns within FIT_MARGIN of them (the map context around the pair; zoom out with -)
  const FIT_MARGIN = 4;
  function fit() {
    if (selected < 0) return;
    const r = rels[selected], p = SCANS[r.i].p, at = [[0, 0], [r.delta[0], r.delta[1]]];
    if (r.estimate) at.push([r.estimate[0], r.estimate[1]]);
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (const [x, y] of at) { x0 = Math.min(x0, x); x1 = Math.max(x1, x); y0 = Math.min(y0, y); y1 = Math.max(y1, y); }
    const near = [x0 - FIT_MARGIN, x1 + FIT_MARGIN, y0 - FIT_MARGIN, y1 + FIT_MARGIN];
    for (let m = 0; m < p.length; m += 2) {
      if (p[m] < near[0] || p[m] > near[1] || p[m + 1] < near[2] || p[m + 1] > near[3]) continue;
      x0 = Math.min(x0, p[m]); x1 = Math.max(x1, p[m]); y0 = Math.min(y0, p[m + 1]); y1 = Math.max(y1, p[m + 1]);
    }
    const s = size();
    view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
    view.scale = 0.85 * Math.min(s.w / Math.max(x1 - x0, 1), s.h / Math.max(y1 - y0, 1));
  }
  function drawPoints(pts, colour, s, half) {
    ctx.fillStyle = colour;
    ctx.beginPath();
    for (let m = 0; m < pts.length; m += 2) {
      const [u, v] = toScreen(pts[m], pts[m + 1], s);
      if (u < -2 || v < -2 || u > s.w + 2 || v > s.h + 2) continue;
      ctx.rect(u - half, v - half, 2 * half, 2 * half);
    }
    ctx.fill();
  }
  function drawPose(d, colour, s, dashed) {
    const [u, v] = toScreen(d[0], d[1], s), a = -d[2];
    ctx.strokeStyle = colour; ctx.lineWidth = 2; ctx.setLineDash(dashed ? [4, 3] : []); ctx.beginPath();
    ctx.moveTo(u + 14 * Math.cos(a), v + 14 * Math.sin(a));
    ctx.lineTo(u + 7 * Math.cos(a + 2.5), v + 7 * Math.sin(a + 2.5));
    ctx.lineTo(u + 7 * Math.cos(a - 2.5), v + 7 * Math.sin(a - 2.5));
    ctx.closePath(); ctx.stroke(); ctx.setLineDash([]);
  }
  function drawLink(a, b, colour, s) {
    const [u1, v1] = toScreen(a[0], a[1], s), [u2, v2] = toScreen(b[0], b[1], s);
    ctx.strokeStyle = colour; ctx.lineWidth = 1; ctx.setLineDash([5, 4]);
    ctx.beginPath(); ctx.moveTo(u1, v1); ctx.lineTo(u2, v2); ctx.stroke(); ctx.setLineDash([]);
  }
  function drawWindow(s) {
    if (!lastWindow || lastWindow.k !== selected) return;
    const [u, v] = toScreen(lastWindow.x0[0] - WIN.xy, lastWindow.x0[1] + WIN.xy, s), side = 2 * WIN.xy * view.scale;
    ctx.strokeStyle = "#0a7d32"; ctx.lineWidth = 1.5; ctx.setLineDash([3, 3]);
    ctx.strokeRect(u, v, Math.max(side, 3), Math.max(side, 3)); ctx.setLineDash([]);
  }
  function draw() {
    const s = size();
    ctx.setTransform(s.dpr, 0, 0, s.dpr, 0, 0);
    ctx.clearRect(0, 0, s.w, s.h);
    if (selected >= 0) {
      const r = rels[selected];
      if (showMap && MAP.length) drawPoints(mapInFrame(r.i), "#b9b9b9", s, 1);
      drawPoints(SCANS[r.i].p, "#1f5fbf", s, 1.5);
      if (r.second) drawPoints(moved(SCANS[r.j], r.second), "rgba(142, 68, 173, 0.35)", s, 1.2);
      drawPoints(moved(SCANS[r.j], r.delta), "#e8710a", s, 1.5);
      drawPose([0, 0, 0], "#1f5fbf", s);
      if (r.estimate) { drawLink(r.delta, r.estimate, "#555", s); drawPose(r.estimate, "#555", s, true); }
      if (r.second) drawPose(r.second, "#8e44ad", s, true);
      drawPose(r.delta, "#e8710a", s);
      drawWindow(s);
    }
    drawInset();
    drawProfile();
  }
  let pending = false;
  function scheduleDraw() {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; draw(); });
  }
  function drawInset() {
    const w = inset.clientWidth, h = inset.clientHeight, dpr = window.devicePixelRatio || 1;
    inset.width = Math.round(w * dpr); inset.height = Math.round(h * dpr);
    ictx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const T = DATA.track && DATA.track.length ? DATA.track : DATA.poses.filter((v, k) => k % 3 !== 2);
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (let k = 0; k < T.length; k += 2) {
      x0 = Math.min(x0, T[k]); x1 = Math.max(x1, T[k]); y0 = Math.min(y0, T[k + 1]); y1 = Math.max(y1, T[k + 1]);
    }
    const sc = 0.9 * Math.min(w / Math.max(x1 - x0, 1e-6), h / Math.max(y1 - y0, 1e-6));
    const at = (x, y) => [w / 2 + (x - (x0 + x1) / 2) * sc, h / 2 - (y - (y0 + y1) / 2) * sc];
    ictx.fillStyle = "#888";
    for (let k = 0; k < T.length; k += 2) { const [u, v] = at(T[k], T[k + 1]); ictx.fillRect(u - 0.5, v - 0.5, 1.2, 1.2); }
    if (selected >= 0) {
      const P = DATA.poses;
      for (const [k, col] of [[rels[selected].i, "#1f5fbf"], [rels[selected].j, "#e8710a"]]) {
        const [u, v] = at(P[3 * k], P[3 * k + 1]);
        ictx.fillStyle = col; ictx.beginPath(); ictx.arc(u, v, 4, 0, 2 * Math.PI); ictx.fill();
      }
    }
  }

  // ------------------------------------------------------------------- text
  const fmt = (v, f, d) => (v === null || v === undefined || !Number.isFinite(v) ? "–" : (v * f).toFixed(d));
  const FLAG = { failed: "F", "not converged": "N", degenerate: "D", "weak geometry": "W", "low overlap": "O",
    "high residual": "R", "large correction": "C", ambiguous: "A" };
  const flagCodes = (f) => (f ? f.split(",").map((x) => x.trim()).filter(Boolean)
    .map((x) => FLAG[x] ?? x.split(" ").map((w) => w[0].toUpperCase()).join("")).join(" ") : "");
  const MARK = { unreviewed: "·", accepted: "✓", rejected: "✗" };
  function counts() {
    const n = { unreviewed: 0, accepted: 0, rejected: 0 };
    rels.forEach((r) => { n[r.status]++; });
    return n;
  }
  function pairInfo(r, k) {
    const d = r.delta, e = r.estimate;
    let text = `#${k + 1}: t1 ${r.t1} → t2 ${r.t2} (Δt ${(r.t2 - r.t1).toFixed(2)} s). ` +
      `x ${d[0].toFixed(4)} m, y ${d[1].toFixed(4)} m, θ ${(d[2] / DEG).toFixed(3)}°` +
      `${r.edited ? " (corrected)" : ""}. `;
    if (e) text += `Estimate's pose ${(100 * Math.hypot(e[0] - d[0], e[1] - d[1])).toFixed(1)} cm, ${(wrap(e[2] - d[2]) / DEG).toFixed(2)}° away. `;
    if (r.second) text += `Second hypothesis ${(100 * Math.hypot(r.second[0] - d[0], r.second[1] - d[1])).toFixed(1)} cm away` +
      `${Number.isFinite(r.secondRatio) ? `, score ratio ${r.secondRatio.toFixed(2)}` : ""}. `;
    return text + `Matched ${fmt(r.matched, 100, 0)}%, residual ${fmt(r.residual, 100, 2)} cm, ` +
      `condition ${fmt(r.condition, 1, 3)}, suspicion ${fmt(r.suspicion, 1, 2)}. Flags: ${r.flags || "none"}. Status: ${r.status}.`;
  }
  function refresh() {
    const n = counts();
    const edited = rels.filter((r) => r.edited && r.status !== "rejected").length;
    $("summary").textContent = `${rels.length} relations${DATA.name ? " of " + DATA.name : ""}: ` +
      `${n.accepted} accepted, ${n.rejected} rejected, ${n.unreviewed} unreviewed; ${edited} corrected`;
    if (selected >= 0) $("pair-info").textContent = pairInfo(rels[selected], selected);
    const body = $("pairs").querySelector("tbody");
    const rows = rels.map((r, k) => k).sort((a, b) => rels[b].suspicion - rels[a].suspicion || a - b).slice(0, 400);
    body.innerHTML = "";
    for (const k of rows) {
      const r = rels[k], tr = document.createElement("tr");
      if (k === selected) tr.className = "selected";
      for (const text of [k + 1, (r.t2 - r.t1).toFixed(1), fmt(r.matched, 100, 0) + "%", fmt(r.residual, 100, 1), flagCodes(r.flags), MARK[r.status] + (r.edited ? "*" : "")]) {
        const td = document.createElement("td"); td.textContent = text; tr.appendChild(td);
      }
      tr.children[4].title = r.flags;
      tr.lastChild.className = r.status === "unreviewed" ? "" : r.status;
      tr.lastChild.title = r.status;
      tr.addEventListener("click", () => select(k));
      body.appendChild(tr);
    }
    scheduleDraw();
  }

  // ------------------------------------------------------------------- save and load
  function relationsText(includeUnreviewed) {
    const all = includeUnreviewed ?? $("include-unreviewed").checked, n = counts();
    const keep = rels.filter((r) => r.status === "accepted" || (all && r.status === "unreviewed"));
    const lines = [
      `# slamrel scan review${DATA.name ? " of " + DATA.name : ""}: ${n.accepted} accepted, ${n.rejected} rejected, ` +
        `${n.unreviewed} unreviewed (of ${rels.length})`,
      `# written: ${keep.length} relations (${all ? "accepted and unreviewed" : "accepted only"})`,
      "# t1 t2 x y z roll pitch yaw",
    ];
    for (const r of keep) lines.push(`${r.t1} ${r.t2} ${r.delta[0]} ${r.delta[1]} 0 0 0 ${r.delta[2]}`);
    return lines.join("\n") + "\n";
  }
  function stateText() {
    return JSON.stringify({ format: "slamrel-scan-review/2", name: DATA.name,
      relations: rels.map((r) => ({ t1: r.t1, t2: r.t2, status: r.status, delta: r.delta, edited: r.edited })) });
  }
  function save() {
    const text = relationsText(), state = stateText();
    $("relations-output").value = text;
    $("state-output").value = state;
    $("outputs").hidden = false;
    for (const [id, t, type] of [["download", text, "text/plain"], ["download-state", state, "application/json"]]) {
      const a = $(id);
      if (a.href) URL.revokeObjectURL(a.href);
      a.href = URL.createObjectURL(new Blob([t], { type })); a.hidden = false;
    }
    const n = counts();
    say(`saved ${text.split("\n").length - 4} relations (${n.accepted} accepted, ${n.rejected} rejected, ` +
      `${n.unreviewed} unreviewed): use the download links, or copy the text below`);
  }
  function load(text) {
    let st;
    try { st = JSON.parse(text); } catch (e) { say("not a review state: " + e.message); return; }
    const formats = ["slamrel-scan-review/1", "slamrel-scan-review/2"];
    if (!st || !formats.includes(st.format) || !Array.isArray(st.relations) || st.relations.length !== rels.length) {
      say("not a review state of this page (format or relation count differ)"); return;
    }
    const status = (s) => (s === "proposed" ? "unreviewed" : s);
    for (let k = 0; k < rels.length; k++) {
      const s = st.relations[k];
      if (s.t1 !== rels[k].t1 || s.t2 !== rels[k].t2) { say(`relation ${k + 1} names other times; nothing loaded`); return; }
      if (!STATES.includes(status(s.status)) || !Array.isArray(s.delta) || s.delta.length !== 3) {
        say(`relation ${k + 1}: status or relation not understood; nothing loaded`); return;
      }
    }
    st.relations.forEach((s, k) => Object.assign(rels[k], { status: status(s.status), delta: s.delta.slice(), edited: !!s.edited }));
    undoStack.length = 0;
    say("review state loaded");
    refresh();
  }

  // ------------------------------------------------------------------- input
  const reset = () => { if (selected >= 0) change(selected, { delta: rels[selected].proposed.slice(), edited: false }); };
  const toggleMap = () => { showMap = !showMap; say(showMap ? "map shown" : "map hidden"); scheduleDraw(); };
  document.addEventListener("keydown", (ev) => {
    if (ev.target instanceof HTMLInputElement || ev.target instanceof HTMLTextAreaElement) return;
    const big = ev.shiftKey, t = big ? 0.1 : 0.01, a = (big ? 1 : 0.1) * DEG;
    const keys = {
      n: () => step(1), p: () => step(-1), a: () => decide("accepted"), r: () => decide("rejected"),
      i: realignWindow, I: realignFree, h: toSecond, m: toggleMap, u: undo, s: save, f: () => { fit(); scheduleDraw(); },
      "0": reset,
      q: () => nudge(0, 0, a), e: () => nudge(0, 0, -a), Q: () => nudge(0, 0, a), E: () => nudge(0, 0, -a),
      ArrowLeft: () => nudge(-t, 0, 0), ArrowRight: () => nudge(t, 0, 0),
      ArrowUp: () => nudge(0, t, 0), ArrowDown: () => nudge(0, -t, 0),
      "+": () => { view.scale *= 1.5; scheduleDraw(); }, "=": () => { view.scale *= 1.5; scheduleDraw(); },
      "-": () => { view.scale /= 1.5; scheduleDraw(); },
    };
    const f = keys[ev.key] ?? keys[ev.key.toLowerCase()];
    if (f) { f(); ev.preventDefault(); }
  });
  let drag = null;
  canvas.addEventListener("mousedown", (ev) => { if (selected >= 0) drag = { x: ev.clientX, y: ev.clientY }; });
  window.addEventListener("mousemove", (ev) => {
    if (!drag) return;
    const dx = (ev.clientX - drag.x) / view.scale, dy = -(ev.clientY - drag.y) / view.scale;
    drag = { x: ev.clientX, y: ev.clientY };
    if (dx || dy) nudge(dx, dy, 0);
  });
  window.addEventListener("mouseup", () => { drag = null; });
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    if (selected < 0) return;
    const a = (ev.shiftKey ? 1 : 0.1) * DEG * (ev.deltaY < 0 ? 1 : -1);
    nudge(0, 0, a);
  }, { passive: false });
  prof.addEventListener("click", (ev) => {
    if (selected < 0) return;
    const box = prof.getBoundingClientRect(), w = weakOf(rels[selected]);
    const s = Math.round(((ev.clientX - box.left - 6) / (box.width - 12) * 2 - 1) * PROFILE.half / PROFILE.step) * PROFILE.step;
    nudge(s * w[0], s * w[1], 0);
    say(`moved ${(100 * s).toFixed(1)} cm along the weak direction`);
  });
  const click = { prev: () => step(-1), next: () => step(1), accept: () => decide("accepted"),
    reject: () => decide("rejected"), realign: realignWindow, second: toSecond, reset, undo,
    fit: () => { fit(); scheduleDraw(); }, save, "toggle-map": toggleMap };
  for (const [id, f] of Object.entries(click)) $(id).addEventListener("click", f);
  $("load").addEventListener("change", (ev) => {
    const file = ev.target.files[0];
    if (file) file.text().then(load);
  });
  window.addEventListener("resize", () => scheduleDraw());

  // for tests and the console
  window.slamrelReview = {
    relations: () => rels.map((r) => ({ status: r.status, delta: r.delta.slice(), edited: r.edited, suspicion: r.suspicion })),
    selected: () => selected, select, scale: () => view.scale, counts,
    icp: (k, x0, box) => icp(SCANS[rels[k].i], SCANS[rels[k].j], x0, box || null),
    windowed,
    profile, relationsText, stateText, load, mapPoints: () => MAP.length / 2,
  };
  refresh();
})();
