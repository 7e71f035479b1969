// slamrel association review: one canvas, no library, no network (see slamrel/review/page.py).
// State: the proposed pairs plus pairs drawn by hand, each with a status; every change is one
// undoable action. Save writes the CSV that `slamrel map-compare --associate FILE` reads.
"use strict";
(function () {
  const DATA = JSON.parse(document.getElementById("review-data").textContent);
  const C = DATA.cutoff;
  const EST = DATA.estimate, REF = DATA.reference;
  const $ = (id) => document.getElementById(id);
  const canvas = $("map"), ctx = canvas.getContext("2d");

  // ---------------------------------------------------------------- pairs and their status
  // status: "proposed" (undecided), "accepted", "rejected", "added" (drawn by hand)
  const pairs = DATA.pairs.estimate.map((e, k) => ({
    e, r: DATA.pairs.reference[k], residual: DATA.pairs.residual[k],
    // null in the JSON: no second candidate (margin) / a second one at distance 0 (suspicion)
    margin: DATA.pairs.margin[k], suspicion: DATA.pairs.suspicion[k] ?? Infinity,
    status: "proposed", proposed: true,
  }));
  const estIndex = new Map(EST.ids.map((id, k) => [id, k]));
  const refIndex = new Map(REF.ids.map((id, k) => [id, k]));
  const undoStack = [];
  let selected = -1;      // index into pairs
  let drawing = false;    // "draw pair" mode: the next two clicks pick landmarks
  let picked = null;      // {side: "e"|"r", row} first landmark of a pair being drawn
  let minResidual = 0, undecidedOnly = false;
  const timings = { firstPaint: null, firstFrame: null, lastRender: null };  // ms

  const active = (p) => p.status !== "rejected";
  const visible = (p) => p.residual >= minResidual && (!undecidedOnly || p.status === "proposed");

  // nearest other landmark (for the residual / margin of a hand-drawn pair)
  function nearestOther(xs, ys, x, y, skip) {
    let best = Infinity;
    for (let k = 0; k < xs.length; k++) {
      if (k === skip) continue;
      const d = Math.hypot(xs[k] - x, ys[k] - y);
      if (d < best) best = d;
    }
    return best;
  }
  function scored(e, r) {
    const x = EST.x[e], y = EST.y[e], residual = Math.hypot(x - REF.x[r], y - REF.y[r]);
    const d2 = Math.min(nearestOther(REF.x, REF.y, x, y, r),
      nearestOther(EST.x, EST.y, REF.x[r], REF.y[r], e));
    const ratio = residual === 0 ? 0 : (d2 > 0 ? residual / d2 : Infinity);
    return { residual, margin: Number.isFinite(d2) ? d2 - residual : null,
      suspicion: Math.max(residual / C, ratio) };
  }

  // An action is a list of changes [index, before, after] plus the number of pairs it appended.
  function apply(changes, appended) {
    undoStack.push({ changes, appended });
    for (const [k, , after] of changes) pairs[k].status = after;
    refresh();
  }
  function setStatus(k, status) {
    if (k < 0 || pairs[k].status === status) return;
    apply([[k, pairs[k].status, status]], 0);
  }
  function undo() {
    const act = undoStack.pop();
    if (!act) { say("nothing to undo"); return; }
    for (const [k, before] of act.changes) pairs[k].status = before;
    pairs.length -= act.appended;
    // show what was undone: the first pair it changed (if it still exists)
    selected = act.changes.length && act.changes[0][0] < pairs.length ? act.changes[0][0] : -1;
    say("undone");
    refresh();
  }
  // Pair estimate row e with reference row r; pairs that used either become rejected.
  function makePair(e, r) {
    const changes = [];
    let existing = -1;
    pairs.forEach((p, k) => {
      if (p.e === e && p.r === r) existing = k;
      else if (active(p) && (p.e === e || p.r === r)) changes.push([k, p.status, "rejected"]);
    });
    let appended = 0;
    if (existing >= 0) {
      const p = pairs[existing];
      const want = p.proposed ? "accepted" : "added";
      if (p.status !== want) changes.push([existing, p.status, want]);
    } else {
      pairs.push(Object.assign({ e, r, status: "added", proposed: false }, scored(e, r)));
      existing = pairs.length - 1;
      appended = 1;
    }
    selected = existing;
    apply(changes, appended);
    say(`paired estimate ${EST.ids[e]} with reference ${REF.ids[r]}`);
  }

  // ------------------------------------------------------------------- navigation by suspicion
  function suspiciousOrder() {
    const idx = [];
    pairs.forEach((p, k) => { if (p.status === "proposed" && visible(p)) idx.push(k); });
    return idx.sort((a, b) => pairs[b].suspicion - pairs[a].suspicion || a - b);
  }
  function step(dir) {
    const order = suspiciousOrder();
    if (!order.length) { say("no undecided pair left in the filter"); return; }
    let pos = order.indexOf(selected);
    pos = pos < 0 ? (dir > 0 ? 0 : order.length - 1) : (pos + dir + order.length) % order.length;
    select(order[pos], true);
  }
  function decide(status) {
    if (selected < 0) { say("select a pair first (n)"); return; }
    const k = selected;
    setStatus(k, status);
    // go on with the most suspicious undecided pair (the common path: n, a/r, a/r, ...)
    const order = suspiciousOrder();
    if (order.length) select(order[0], true);
  }
  function select(k, centre) {
    selected = k;
    if (centre && k >= 0) {
      const p = pairs[k];
      view.cx = (EST.x[p.e] + REF.x[p.r]) / 2;
      view.cy = (EST.y[p.e] + REF.y[p.r]) / 2;
      // frame the pair with its neighbourhood: 4 residuals, at least 6 c across
      view.scale = Math.min(view.w, view.h) / Math.max(4 * p.residual, 6 * C);
    }
    refresh();
  }

  // ------------------------------------------------------------------------- view and drawing
  const view = { cx: 0, cy: 0, scale: 1, w: 1, h: 1 };
  const sx = (x) => (x - view.cx) * view.scale + view.w / 2;
  const sy = (y) => view.h / 2 - (y - view.cy) * view.scale;
  function fit() {
    const xs = EST.x.concat(REF.x), ys = EST.y.concat(REF.y);
    let x0 = Infinity, x1 = -Infinity, y0 = Infinity, y1 = -Infinity;
    for (let k = 0; k < xs.length; k++) {
      x0 = Math.min(x0, xs[k]); x1 = Math.max(x1, xs[k]);
      y0 = Math.min(y0, ys[k]); y1 = Math.max(y1, ys[k]);
    }
    view.cx = (x0 + x1) / 2; view.cy = (y0 + y1) / 2;
    view.scale = 0.92 * Math.min(view.w / Math.max(x1 - x0, 1e-9), view.h / Math.max(y1 - y0, 1e-9));
    render();
  }
  function resize() {
    const r = canvas.getBoundingClientRect(), dpr = window.devicePixelRatio || 1;
    view.w = Math.max(r.width, 1); view.h = Math.max(r.height, 1);
    canvas.width = Math.round(view.w * dpr); canvas.height = Math.round(view.h * dpr);
    ctx.setTransform(dpr, 0, 0, dpr, 0, 0);
  }

  // residual colour: green at 0, amber at c/2, red from c on (8 bins, one path per bin)
  const BINS = ["#1a9850", "#66bd63", "#a6d96a", "#d9ef8b", "#fee08b", "#fdae61", "#f46d43", "#d73027"];
  const bin = (res) => Math.min(BINS.length - 1, Math.floor((res / C) * BINS.length));

  function render() {
    const t0 = performance.now();
    ctx.clearRect(0, 0, view.w, view.h);
    const paths = BINS.map(() => new Path2D()), rejected = new Path2D();
    const estUsed = new Uint8Array(EST.ids.length), refUsed = new Uint8Array(REF.ids.length);
    for (const p of pairs) {
      if (active(p)) { estUsed[p.e] = 1; refUsed[p.r] = 1; }
      if (!visible(p)) continue;
      const path = active(p) ? paths[bin(p.residual)] : rejected;
      path.moveTo(sx(EST.x[p.e]), sy(EST.y[p.e]));
      path.lineTo(sx(REF.x[p.r]), sy(REF.y[p.r]));
    }
    ctx.lineWidth = 2;
    BINS.forEach((c, k) => { ctx.strokeStyle = c; ctx.stroke(paths[k]); });
    ctx.setLineDash([4, 3]); ctx.strokeStyle = "#999"; ctx.lineWidth = 1;
    ctx.stroke(rejected);
    ctx.setLineDash([]);
    // reference: circles (blue when paired, black and larger when missed)
    const refPaired = new Path2D(), refMissed = new Path2D();
    for (let k = 0; k < REF.ids.length; k++) {
      const x = sx(REF.x[k]), y = sy(REF.y[k]), rad = refUsed[k] ? 4 : 6;
      if (x < -10 || y < -10 || x > view.w + 10 || y > view.h + 10) continue;
      const path = refUsed[k] ? refPaired : refMissed;
      path.moveTo(x + rad, y); path.arc(x, y, rad, 0, 2 * Math.PI);
    }
    ctx.lineWidth = 1.5; ctx.strokeStyle = "#1f4e9c"; ctx.stroke(refPaired);
    ctx.lineWidth = 2.5; ctx.strokeStyle = "#000"; ctx.stroke(refMissed);
    // estimate: filled squares (orange when paired, magenta and larger when spurious)
    for (let k = 0; k < EST.ids.length; k++) {
      const x = sx(EST.x[k]), y = sy(EST.y[k]), h = estUsed[k] ? 2.5 : 4;
      if (x < -10 || y < -10 || x > view.w + 10 || y > view.h + 10) continue;
      ctx.fillStyle = estUsed[k] ? "#e66101" : "#c51b7d";
      ctx.fillRect(x - h, y - h, 2 * h, 2 * h);
    }
    if (selected >= 0) {
      const p = pairs[selected];
      ctx.lineWidth = 2; ctx.strokeStyle = "#000";
      for (const [x, y] of [[EST.x[p.e], EST.y[p.e]], [REF.x[p.r], REF.y[p.r]]]) {
        ctx.beginPath(); ctx.arc(sx(x), sy(y), 11, 0, 2 * Math.PI); ctx.stroke();
      }
    }
    if (picked) {
      const xs = picked.side === "e" ? EST : REF;
      ctx.lineWidth = 3; ctx.strokeStyle = "#6d28d9";
      ctx.beginPath(); ctx.arc(sx(xs.x[picked.row]), sy(xs.y[picked.row]), 9, 0, 2 * Math.PI);
      ctx.stroke();
    }
    timings.lastRender = performance.now() - t0;
    return { estUsed, refUsed };
  }

  // ----------------------------------------------------------------------- panel and summary
  const fmt = (v) => (v === null || v === undefined ? "–" : !Number.isFinite(v) ? "∞"
    : Math.abs(v) >= 100 ? v.toFixed(1) : Number(v.toPrecision(3)).toString());
  const LIST_MAX = 200;

  function refresh() {
    const { estUsed, refUsed } = render();
    const n = { proposed: 0, accepted: 0, rejected: 0, added: 0 };
    for (const p of pairs) n[p.status]++;
    const matched = n.proposed + n.accepted + n.added;
    const missed = refUsed.length - refUsed.reduce((a, b) => a + b, 0);
    const spurious = estUsed.length - estUsed.reduce((a, b) => a + b, 0);
    $("summary").textContent = `${EST.ids.length} estimated, ${REF.ids.length} reference landmarks; ` +
      `matched ${matched}, missed ${missed}, spurious ${spurious}; ` +
      `${n.proposed} undecided, ${n.accepted} accepted, ${n.rejected} rejected, ${n.added} drawn`;
    const order = [];
    pairs.forEach((p, k) => { if (visible(p)) order.push(k); });
    order.sort((a, b) => pairs[b].suspicion - pairs[a].suspicion || a - b);
    const rows = order.slice(0, LIST_MAX).map((k) => {
      const p = pairs[k];
      return `<tr data-k="${k}" class="${p.status}${k === selected ? " selected" : ""}">` +
        `<td>${EST.ids[p.e]}</td><td>${REF.ids[p.r]}</td><td>${fmt(p.residual)}</td>` +
        `<td>${fmt(p.margin)}</td><td>${p.status}</td></tr>`;
    });
    $("pairs").tBodies[0].innerHTML = rows.join("");
    $("list-note").textContent = order.length > LIST_MAX
      ? `the ${LIST_MAX} most suspicious of ${order.length} pairs in the filter`
      : `${order.length} pairs in the filter`;
    listUnmatched(estUsed, refUsed);
    if (selected >= 0) {
      const p = pairs[selected];
      $("pair-info").textContent = `estimate ${EST.ids[p.e]} ↔ reference ${REF.ids[p.r]}: ` +
        `residual ${fmt(p.residual)} m, margin ${fmt(p.margin)} m, ` +
        `suspicion ${fmt(p.suspicion)}, ${p.status}`;
    } else {
      $("pair-info").textContent = "No pair selected: press n for the most suspicious one.";
    }
    $("draw").classList.toggle("on", drawing);
    canvas.classList.toggle("drawing", drawing);
  }
  // Spurious estimates with the nearest missed reference landmark: the usual correction is to
  // pair the two (click a row, then the reference landmark).
  function listUnmatched(estUsed, refUsed) {
    const est = [], ref = [];
    estUsed.forEach((u, k) => { if (!u) est.push(k); });
    refUsed.forEach((u, k) => { if (!u) ref.push(k); });
    const rows = est.slice(0, LIST_MAX).map((e) => {
      let best = -1, bestD = Infinity;
      for (const r of ref) {
        const d = Math.hypot(EST.x[e] - REF.x[r], EST.y[e] - REF.y[r]);
        if (d < bestD) { bestD = d; best = r; }
      }
      return [e, best, bestD];
    }).sort((a, b) => a[2] - b[2]);
    $("unmatched").tBodies[0].innerHTML = rows.map(([e, r, d]) =>
      `<tr data-e="${e}"><td>${EST.ids[e]}</td><td>${r < 0 ? "–" : REF.ids[r]}</td>` +
      `<td>${fmt(d)}</td></tr>`).join("");
    $("unmatched-note").textContent = `${est.length} estimated and ${ref.length} reference ` +
      "landmarks without a pair; click a row, then a reference landmark, to pair them";
  }
  function say(text) { $("status").textContent = text; }

  // ------------------------------------------------------------------------- association CSV
  function csv() {
    const act = pairs.filter(active).sort((a, b) => a.r - b.r);
    const used = new Set(act.map((p) => p.r)), usedE = new Set(act.map((p) => p.e));
    const missed = REF.ids.filter((_, k) => !used.has(k));
    const spurious = EST.ids.filter((_, k) => !usedE.has(k));
    const open = act.filter((p) => p.status === "proposed").map((p) => `${EST.ids[p.e]}:${REF.ids[p.r]}`);
    const lines = [
      `# slamrel association review: estimate ${oneLine(DATA.names.estimate)}, ` +
        `reference ${oneLine(DATA.names.reference)}`,
      `# missed reference ids: ${missed.join(" ")}`,
      `# spurious estimate ids: ${spurious.join(" ")}`,
      `# unreviewed: ${open.join(" ")}`,
      "estimate,reference",
      ...act.map((p) => `${EST.ids[p.e]},${REF.ids[p.r]}`),
    ];
    return lines.join("\n") + "\n";
  }
  const oneLine = (text) => String(text).replace(/\s+/g, " ");  // a comment stays one line
  let downloadUrl = null;
  function save() {
    const text = csv();
    $("csv-output").value = text;
    if (downloadUrl) URL.revokeObjectURL(downloadUrl);
    downloadUrl = URL.createObjectURL(new Blob([text], { type: "text/csv" }));
    const a = $("download");
    a.href = downloadUrl; a.hidden = false;
    say("saved: use the download link (or copy the text below)");
    return text;
  }
  // Read a CSV written by this page or by `map-compare --write-association`; resume from it.
  function loadCsv(text) {
    const open = new Set(), want = new Map(), seenE = new Set(), seenR = new Set();
    let header = false;
    const lines = text.split(/\r?\n/);
    for (let n = 0; n < lines.length; n++) {
      const line = lines[n].trim(), where = `line ${n + 1}`;
      if (line.startsWith("# unreviewed:")) {
        line.slice(13).trim().split(/\s+/).filter(Boolean).forEach((t) => open.add(t));
      }
      if (!line || line.startsWith("#")) continue;
      if (!header) {
        if (line.toLowerCase().replace(/\s/g, "") !== "estimate,reference") {
          throw new Error(`${where}: expected the header 'estimate,reference'`);
        }
        header = true; continue;
      }
      const f = line.split(",").map((s) => s.trim());
      if (f.length !== 2 || !/^-?\d+$/.test(f[0]) || !/^-?\d+$/.test(f[1])) {
        throw new Error(`${where}: expected two integer ids, got '${line}'`);
      }
      const e = estIndex.get(Number(f[0])), r = refIndex.get(Number(f[1]));
      if (e === undefined) throw new Error(`${where}: unknown estimated landmark id ${f[0]}`);
      if (r === undefined) throw new Error(`${where}: unknown reference landmark id ${f[1]}`);
      if (seenE.has(e)) throw new Error(`${where}: estimated landmark ${f[0]} is associated twice`);
      if (seenR.has(r)) throw new Error(`${where}: reference landmark ${f[1]} is associated twice`);
      seenE.add(e); seenR.add(r);
      want.set(`${f[0]}:${f[1]}`, [e, r]);
    }
    if (!header) throw new Error("expected the header 'estimate,reference'");
    pairs.length = DATA.pairs.estimate.length;  // drop hand-drawn pairs, then re-add from file
    for (const p of pairs) {
      const key = `${EST.ids[p.e]}:${REF.ids[p.r]}`;
      p.status = !want.has(key) ? "rejected" : open.has(key) ? "proposed" : "accepted";
      want.delete(key);
    }
    for (const [, [e, r]] of want) {
      pairs.push(Object.assign({ e, r, status: "added", proposed: false }, scored(e, r)));
    }
    undoStack.length = 0; selected = -1;
    refresh();
  }

  // ----------------------------------------------------------------------------- interaction
  function landmarkAt(px, py, side) {
    let best = null, bestD = 10;  // pixels
    for (const [s, m] of [["e", EST], ["r", REF]]) {
      if (side && s !== side) continue;
      for (let k = 0; k < m.ids.length; k++) {
        const d = Math.hypot(sx(m.x[k]) - px, sy(m.y[k]) - py);
        if (d < bestD) { bestD = d; best = { side: s, row: k }; }
      }
    }
    return best;
  }
  function click(px, py, shift) {
    if (drawing || shift) {
      const hit = landmarkAt(px, py, picked ? (picked.side === "e" ? "r" : "e") : null);
      if (!hit) { say("no landmark there: click closer to one (Esc cancels)"); return; }
      if (!picked) {
        picked = hit; drawing = true;
        say(`${hit.side === "e" ? "estimate" : "reference"} ${(hit.side === "e" ? EST : REF).ids[hit.row]}` +
          ` picked: now click a${hit.side === "e" ? " reference" : "n estimated"} landmark`);
        refresh(); return;
      }
      const [e, r] = picked.side === "e" ? [picked.row, hit.row] : [hit.row, picked.row];
      picked = null; drawing = false;
      makePair(e, r); return;
    }
    const hit = landmarkAt(px, py, null);
    if (!hit) { selected = -1; refresh(); return; }
    const k = pairs.findIndex((p) => active(p) && (hit.side === "e" ? p.e : p.r) === hit.row);
    const m = hit.side === "e" ? EST : REF;
    say(`${hit.side === "e" ? "estimate" : "reference"} ${m.ids[hit.row]}` +
      (k < 0 ? ": not paired (press d and click two landmarks to pair it)" : ""));
    select(k, false);
  }

  let drag = null;
  canvas.addEventListener("mousedown", (ev) => {
    drag = { x: ev.clientX, y: ev.clientY, cx: view.cx, cy: view.cy, moved: false };
  });
  window.addEventListener("mousemove", (ev) => {
    if (!drag) return;
    const dx = ev.clientX - drag.x, dy = ev.clientY - drag.y;
    if (Math.abs(dx) + Math.abs(dy) > 3) drag.moved = true;
    if (drag.moved) {
      view.cx = drag.cx - dx / view.scale; view.cy = drag.cy + dy / view.scale; render();
    }
  });
  window.addEventListener("mouseup", (ev) => {
    if (drag && !drag.moved && ev.target === canvas) {
      const r = canvas.getBoundingClientRect();
      click(ev.clientX - r.left, ev.clientY - r.top, ev.shiftKey);
    }
    drag = null;
  });
  function zoom(factor, px, py) {
    const wx = view.cx + (px - view.w / 2) / view.scale, wy = view.cy - (py - view.h / 2) / view.scale;
    view.scale *= factor;
    view.cx = wx - (px - view.w / 2) / view.scale; view.cy = wy + (py - view.h / 2) / view.scale;
    render();
  }
  canvas.addEventListener("wheel", (ev) => {
    ev.preventDefault();
    const r = canvas.getBoundingClientRect();
    zoom(Math.pow(1.2, -Math.sign(ev.deltaY)), ev.clientX - r.left, ev.clientY - r.top);
  }, { passive: false });

  function toggleDraw() {
    drawing = !drawing; picked = null;
    say(drawing ? "draw a pair: click an estimated and a reference landmark (Esc cancels)" : "");
    refresh();
  }
  $("prev").onclick = () => step(-1);
  $("next").onclick = () => step(1);
  $("accept").onclick = () => decide("accepted");
  $("reject").onclick = () => decide("rejected");
  $("draw").onclick = toggleDraw;
  $("undo").onclick = undo;
  $("fit").onclick = fit;
  $("save").onclick = save;
  $("min-residual").addEventListener("input", (ev) => {
    minResidual = Number(ev.target.value);
    $("min-residual-value").textContent = fmt(minResidual);
    refresh();
  });
  $("undecided-only").addEventListener("change", (ev) => { undecidedOnly = ev.target.checked; refresh(); });
  $("load").addEventListener("change", (ev) => {
    const file = ev.target.files[0];
    if (!file) return;
    file.text().then((text) => {
      try { loadCsv(text); say(`loaded ${file.name}`); } catch (err) { say(`${file.name}: ${err.message}`); }
    });
  });
  $("unmatched").addEventListener("click", (ev) => {
    const tr = ev.target.closest("tr[data-e]");
    if (!tr) return;
    const e = Number(tr.dataset.e);
    view.cx = EST.x[e]; view.cy = EST.y[e];
    view.scale = Math.max(view.scale, Math.min(view.w, view.h) / (10 * C));
    drawing = true; picked = { side: "e", row: e }; selected = -1;
    say(`estimate ${EST.ids[e]} picked: now click a reference landmark (Esc cancels)`);
    refresh();
  });
  $("pairs").addEventListener("click", (ev) => {
    const tr = ev.target.closest("tr[data-k]");
    if (tr) select(Number(tr.dataset.k), true);
  });
  document.addEventListener("keydown", (ev) => {
    if (ev.target instanceof Element && ev.target.closest("input, textarea")) return;
    if ((ev.ctrlKey || ev.metaKey) && ev.key === "z") { ev.preventDefault(); undo(); return; }
    if (ev.ctrlKey || ev.metaKey || ev.altKey) return;
    const keys = {
      n: () => step(1), j: () => step(1), p: () => step(-1), k: () => step(-1),
      a: () => decide("accepted"), r: () => decide("rejected"), x: () => decide("rejected"),
      d: toggleDraw, u: undo, f: fit, s: save,
      "+": () => zoom(1.5, view.w / 2, view.h / 2), "-": () => zoom(1 / 1.5, view.w / 2, view.h / 2),
      Escape: () => { drawing = false; picked = null; say(""); refresh(); },
    };
    if (keys[ev.key]) { ev.preventDefault(); keys[ev.key](); }
  });
  // the canvas follows its box (window resized, header text wrapped): keep the view centre
  new ResizeObserver(() => { resize(); render(); }).observe(canvas);

  // --------------------------------------------------------------------------------- start
  const maxRes = DATA.pairs.residual.reduce((a, b) => Math.max(a, b), C);
  $("min-residual").max = String(maxRes);
  $("legend").innerHTML = BINS.map((c, k) =>
    `<span class="swatch" style="background:${c}"></span>`).join("") +
    `<div>pair residual 0 → ${fmt(C)} m (c) and beyond; dashed grey: rejected</div>` +
    `<div><span style="color:#1f4e9c">○</span> reference, <b>○</b> missed reference, ` +
    `<span style="color:#e66101">■</span> estimate (aligned), ` +
    `<span style="color:#c51b7d">■</span> spurious estimate</div>`;
  const al = DATA.alignment;
  $("alignment").textContent = `Alignment (${al.source}): rotation ` +
    `${fmt((al.angle * 180) / Math.PI)}°, translation (${fmt(al.translation[0])}, ` +
    `${fmt(al.translation[1])}) m.`;
  resize(); fit(); refresh();
  timings.firstPaint = performance.now();  // ms since navigation start, after the first frame's drawing
  requestAnimationFrame(() => { timings.firstFrame = performance.now(); });

  // for tests and scripting: the page's state and its CSV, without a download
  window.slamrelReview = {
    csv, save, loadCsv, undo, timings,
    select: (k) => select(k, true),
    pairs: () => pairs.map((p) => ({ estimate: EST.ids[p.e], reference: REF.ids[p.r],
      status: p.status, residual: p.residual })),
    findPair: (estId, refId) => pairs.findIndex((p) => EST.ids[p.e] === estId && REF.ids[p.r] === refId),
    // CSS pixels of a landmark relative to the canvas's top-left corner
    screenOf: (side, id) => {
      const m = side === "estimate" ? EST : REF, k = (side === "estimate" ? estIndex : refIndex).get(id);
      return [sx(m.x[k]), sy(m.y[k])];
    },
    canvasSize: () => [view.w, view.h],
  };
})();
