// slamrel scan relation review: one canvas, no library, no network (see slamrel/review/scans.py).
// State: one entry per proposed relation with a status and the relation shown; every change
// is one undoable action. Save writes a Freiburg .relations file and the review state.
"use strict";
(function () {
  const DATA = JSON.parse(document.getElementById("review-data").textContent);
  const R = DATA.relations, SCANS = DATA.scans, ICP = DATA.icp;
  const $ = (id) => document.getElementById(id);
  const canvas = $("map"), ctx = canvas.getContext("2d");
  const inset = $("inset"), ictx = inset.getContext("2d");
  const DEG = Math.PI / 180;

  const rels = R.t1.map((t1, k) => ({
    t1, t2: R.t2[k], i: R.i[k], j: R.j[k],
    proposed: R.delta.slice(3 * k, 3 * k + 3), delta: R.delta.slice(3 * k, 3 * k + 3),
    matched: R.matched[k], residual: R.residual[k], condition: R.condition[k],
    flags: R.flags[k], suspicion: R.suspicion[k] ?? Infinity,
    status: "proposed", edited: false,
  }));
  const undoStack = [];
  let selected = -1;
  const view = { cx: 0, cy: 0, scale: 40 };

  function say(text) { $("status").textContent = text; }
  const wrap = (a) => Math.atan2(Math.sin(a), Math.cos(a));

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

  // ------------------------------------------------------------------- navigation
  function order() {
    const idx = [];
    rels.forEach((r, k) => { if (r.status === "proposed") idx.push(k); });
    return idx.sort((a, b) => rels[b].suspicion - rels[a].suspicion || a - b);
  }
  function step(dir) {
    const o = order();
    if (!o.length) { say("no undecided relation left"); return; }
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
  function select(k) { selected = k; fit(); refresh(); }

  // ------------------------------------------------------------------- geometry
  function moved(scan, d) {
    const c = Math.cos(d[2]), s = Math.sin(d[2]), p = scan.p, out = new Float64Array(p.length);
    for (let m = 0; m < p.length; m += 2) {
      out[m] = c * p[m] - s * p[m + 1] + d[0];
      out[m + 1] = s * p[m] + c * p[m + 1] + d[1];
    }
    return out;
  }
  // Point-to-line ICP, as slamrel.scans.matching.align: nearest line centroid within the gate,
  // trimmed share, Cauchy weights on the robust scale, Gauss-Newton on [tx, ty, theta].
  function icp(ref, cur, x0) {
    const x = x0.slice(), L = ref.c.length / 2;
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
        let best = gate * gate, b = -1;
        for (let l = 0; l < L; l++) {
          const dx = q[m] - ref.c[2 * l], dy = q[m + 1] - ref.c[2 * l + 1], d2 = dx * dx + dy * dy;
          if (d2 < best) { best = d2; b = l; }
        }
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
      x[0] -= dxv[0]; x[1] -= dxv[1]; x[2] -= dxv[2];
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
  function realign() {
    if (selected < 0) { say("select a relation first (n)"); return; }
    const r = rels[selected], t0 = performance.now();
    const out = icp(SCANS[r.i], SCANS[r.j], r.delta);
    if (!out.ok) { say("re-align failed: too few matches from here"); return; }
    change(selected, { delta: out.delta, edited: true });
    say(`re-aligned in ${(performance.now() - t0).toFixed(0)} ms: matched ${(100 * out.matched).toFixed(0)}%, ` +
      `residual ${(100 * out.rms).toFixed(1)} cm${out.converged ? "" : " (not converged)"}`);
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
  function fit() {
    if (selected < 0) return;
    const p = SCANS[rels[selected].i].p;
    const xs = [], ys = [];
    for (let m = 0; m < p.length; m += 2) { xs.push(p[m]); ys.push(p[m + 1]); }
    xs.sort((a, b) => a - b); ys.sort((a, b) => a - b);
    const q = (a, f) => a[Math.min(a.length - 1, Math.floor(f * a.length))] ?? 0;
    const x0 = Math.min(q(xs, 0.02), 0), x1 = Math.max(q(xs, 0.98), 0);
    const y0 = Math.min(q(ys, 0.02), 0), y1 = Math.max(q(ys, 0.98), 0);
    const s = size();
    view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
    view.scale = 0.9 * Math.min(s.w / Math.max(x1 - x0, 1), s.h / Math.max(y1 - y0, 1));
  }
  function drawPoints(pts, colour, s) {
    ctx.fillStyle = colour;
    for (let m = 0; m < pts.length; m += 2) {
      const [u, v] = toScreen(pts[m], pts[m + 1], s);
      ctx.fillRect(u - 1.5, v - 1.5, 3, 3);
    }
  }
  function drawPose(d, colour, s) {
    const [u, v] = toScreen(d[0], d[1], s), a = -d[2];
    ctx.strokeStyle = colour; ctx.lineWidth = 2; ctx.beginPath();
    ctx.moveTo(u + 12 * Math.cos(a), v + 12 * Math.sin(a));
    ctx.lineTo(u + 6 * Math.cos(a + 2.5), v + 6 * Math.sin(a + 2.5));
    ctx.lineTo(u + 6 * Math.cos(a - 2.5), v + 6 * Math.sin(a - 2.5));
    ctx.closePath(); ctx.stroke();
  }
  function draw() {
    const s = size();
    ctx.setTransform(s.dpr, 0, 0, s.dpr, 0, 0);
    ctx.clearRect(0, 0, s.w, s.h);
    if (selected >= 0) {
      const r = rels[selected];
      drawPoints(SCANS[r.i].p, "#1f5fbf", s);
      drawPoints(moved(SCANS[r.j], r.delta), "#e8710a", s);
      drawPose([0, 0, 0], "#1f5fbf", s);
      drawPose(r.delta, "#e8710a", s);
    }
    drawInset();
  }
  function drawInset() {
    const w = inset.clientWidth, h = inset.clientHeight, dpr = window.devicePixelRatio || 1;
    inset.width = Math.round(w * dpr); inset.height = Math.round(h * dpr);
    ictx.setTransform(dpr, 0, 0, dpr, 0, 0);
    const P = DATA.poses;
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (let k = 0; k < P.length; k += 3) {
      x0 = Math.min(x0, P[k]); x1 = Math.max(x1, P[k]); y0 = Math.min(y0, P[k + 1]); y1 = Math.max(y1, P[k + 1]);
    }
    const sc = 0.9 * Math.min(w / Math.max(x1 - x0, 1e-6), h / Math.max(y1 - y0, 1e-6));
    const at = (k) => [w / 2 + (P[3 * k] - (x0 + x1) / 2) * sc, h / 2 - (P[3 * k + 1] - (y0 + y1) / 2) * sc];
    ictx.fillStyle = "#888";
    for (let k = 0; k < P.length / 3; k++) { const [u, v] = at(k); ictx.fillRect(u - 0.5, v - 0.5, 1.2, 1.2); }
    if (selected >= 0) {
      for (const [k, col] of [[rels[selected].i, "#1f5fbf"], [rels[selected].j, "#e8710a"]]) {
        const [u, v] = at(k);
        ictx.fillStyle = col; ictx.beginPath(); ictx.arc(u, v, 4, 0, 2 * Math.PI); ictx.fill();
      }
    }
  }

  // ------------------------------------------------------------------- text
  const fmt = (v, f, d) => (v === null || v === undefined || !Number.isFinite(v) ? "–" : (v * f).toFixed(d));
  function refresh() {
    const n = { proposed: 0, accepted: 0, rejected: 0 };
    rels.forEach((r) => { n[r.status]++; });
    const edited = rels.filter((r) => r.edited && r.status !== "rejected").length;
    $("summary").textContent = `${rels.length} relations${DATA.name ? " of " + DATA.name : ""}: ` +
      `${n.accepted} accepted, ${n.rejected} rejected, ${n.proposed} undecided; ${edited} corrected`;
    if (selected >= 0) {
      const r = rels[selected], d = r.delta;
      $("pair-info").innerHTML = "";
      $("pair-info").textContent = `#${selected + 1}: t1 ${r.t1} → t2 ${r.t2} (Δt ${(r.t2 - r.t1).toFixed(2)} s). ` +
        `x ${d[0].toFixed(4)} m, y ${d[1].toFixed(4)} m, θ ${(d[2] / DEG).toFixed(3)}°` +
        `${r.edited ? " (corrected)" : ""}. Matched ${fmt(r.matched, 100, 0)}%, residual ${fmt(r.residual, 100, 2)} cm, ` +
        `condition ${fmt(r.condition, 1, 3)}, suspicion ${fmt(r.suspicion, 1, 2)}. ` +
        `Flags: ${r.flags || "none"}. Status: ${r.status}.`;
    }
    const body = $("pairs").querySelector("tbody");
    const rows = rels.map((r, k) => k).sort((a, b) => rels[b].suspicion - rels[a].suspicion || a - b).slice(0, 300);
    body.innerHTML = "";
    for (const k of rows) {
      const r = rels[k], tr = document.createElement("tr");
      if (k === selected) tr.className = "selected";
      for (const text of [k + 1, (r.t2 - r.t1).toFixed(1), fmt(r.matched, 100, 0) + "%", fmt(r.residual, 100, 2), r.flags, r.status + (r.edited ? "*" : "")]) {
        const td = document.createElement("td"); td.textContent = text; tr.appendChild(td);
      }
      tr.lastChild.className = r.status === "proposed" ? "" : r.status;
      tr.addEventListener("click", () => select(k));
      body.appendChild(tr);
    }
    draw();
  }

  // ------------------------------------------------------------------- save and load
  function relationsText() {
    const lines = ["# t1 t2 x y z roll pitch yaw" + (DATA.name ? ` (reviewed: ${DATA.name})` : "")];
    for (const r of rels) if (r.status !== "rejected") {
      lines.push(`${r.t1} ${r.t2} ${r.delta[0]} ${r.delta[1]} 0 0 0 ${r.delta[2]}`);
    }
    return lines.join("\n") + "\n";
  }
  function stateText() {
    return JSON.stringify({ format: "slamrel-scan-review/1", name: DATA.name,
      relations: rels.map((r) => ({ t1: r.t1, t2: r.t2, status: r.status, delta: r.delta, edited: r.edited })) });
  }
  function save() {
    const text = relationsText(), state = stateText();
    $("relations-output").value = text;
    $("state-output").value = state;
    for (const [id, t, type] of [["download", text, "text/plain"], ["download-state", state, "application/json"]]) {
      const a = $(id);
      if (a.href) URL.revokeObjectURL(a.href);
      a.href = URL.createObjectURL(new Blob([t], { type })); a.hidden = false;
    }
    say("saved: use the download links, or copy the text below");
  }
  function load(text) {
    let st;
    try { st = JSON.parse(text); } catch (e) { say("not a review state: " + e.message); return; }
    if (!st || st.format !== "slamrel-scan-review/1" || !Array.isArray(st.relations) || st.relations.length !== rels.length) {
      say("not a review state of this page (format or relation count differ)"); return;
    }
    for (let k = 0; k < rels.length; k++) {
      const s = st.relations[k];
      if (s.t1 !== rels[k].t1 || s.t2 !== rels[k].t2) { say(`relation ${k + 1} names other times; nothing loaded`); return; }
    }
    st.relations.forEach((s, k) => Object.assign(rels[k], { status: s.status, delta: s.delta.slice(), edited: !!s.edited }));
    undoStack.length = 0;
    say("review state loaded");
    refresh();
  }

  // ------------------------------------------------------------------- input
  document.addEventListener("keydown", (ev) => {
    if (ev.target instanceof HTMLInputElement || ev.target instanceof HTMLTextAreaElement) return;
    const big = ev.shiftKey, t = big ? 0.1 : 0.01, a = (big ? 1 : 0.1) * DEG;
    const keys = {
      n: () => step(1), p: () => step(-1), a: () => decide("accepted"), r: () => decide("rejected"),
      i: realign, u: undo, s: save, f: () => { fit(); draw(); },
      "0": () => { if (selected >= 0) change(selected, { delta: rels[selected].proposed.slice(), edited: false }); },
      q: () => nudge(0, 0, a), e: () => nudge(0, 0, -a), Q: () => nudge(0, 0, a), E: () => nudge(0, 0, -a),
      ArrowLeft: () => nudge(-t, 0, 0), ArrowRight: () => nudge(t, 0, 0),
      ArrowUp: () => nudge(0, t, 0), ArrowDown: () => nudge(0, -t, 0),
      "+": () => { view.scale *= 1.5; draw(); }, "=": () => { view.scale *= 1.5; draw(); },
      "-": () => { view.scale /= 1.5; draw(); },
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
  const click = { prev: () => step(-1), next: () => step(1), accept: () => decide("accepted"),
    reject: () => decide("rejected"), realign, reset: () => keysReset(), undo, fit: () => { fit(); draw(); }, save };
  function keysReset() { if (selected >= 0) change(selected, { delta: rels[selected].proposed.slice(), edited: false }); }
  for (const [id, f] of Object.entries(click)) $(id).addEventListener("click", f);
  $("load").addEventListener("change", (ev) => {
    const file = ev.target.files[0];
    if (file) file.text().then(load);
  });
  window.addEventListener("resize", () => draw());

  // for tests and the console
  window.slamrelReview = {
    relations: () => rels.map((r) => ({ status: r.status, delta: r.delta.slice(), edited: r.edited, suspicion: r.suspicion })),
    selected: () => selected, select, scale: () => view.scale, icp: (k, x0) => icp(SCANS[rels[k].i], SCANS[rels[k].j], x0),
    relationsText, stateText, load,
  };
  refresh();
})();
