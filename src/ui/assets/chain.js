// ---- a Markov loss model: the matrix editor and the drawing of its chain ----
//
// A `ge_lomax` stage is edited as the study's own window shows it: named
// states, the transition matrix as a grid whose rows are kept at 1, an α and
// a λ per state with what they realize, and the chain drawn for any number of
// states (self-loops, arrowheads, probability as colour and width), redrawn
// as the values move. The names are the page's only: the scenario file
// numbers the states (state 1 starts).

const STATE_NAMES = ["Good", "Bad", "Intermediate 1", "Intermediate 2"];
const MAX_STATES = 4;
// Ids of each drawing's markers, unique on the page.
let chainId = 0;

function isChain(stage) {
  return ["ge_lomax", "markov4", "gilbert_elliott"].includes(stage.model);
}

function stateNames(stage) {
  const n = stage.model === "markov4" ? 4 : stage.model === "ge_lomax" ? stage.transition.length : 2;
  if (stage.model === "markov4") return ["1 received", "2 lost (burst)", "3 received (burst)", "4 lost (isolated)"];
  if (!stage._names || stage._names.length !== n) stage._names = STATE_NAMES.slice(0, n);
  return stage._names;
}

// The chain's full matrix, self-loops included, whatever the model.
function chainMatrix(st) {
  const n = (v) => Number(asNumber(v));
  if (st.model === "ge_lomax") return st.transition.map((r) => r.map(Number));
  if (st.model === "gilbert_elliott") return [[1 - n(st.p), n(st.p)], [n(st.r), 1 - n(st.r)]];
  const [p13, p31, p32, p23, p14] = ["p13", "p31", "p32", "p23", "p14"].map((k) => n(st[k]));
  return [
    [1 - p13 - p14, 0, p13, p14],
    [0, 1 - p23, p23, 0],
    [p31, p32, 1 - p31 - p32, 0],
    [1, 0, 0, 0],
  ];
}

// White to dark blue as p goes from 0 to 1.
function probColour(p) {
  const t = Math.max(0, Math.min(1, p));
  const mix = (a, b) => Math.round(a + (b - a) * t);
  return `rgb(${mix(198, 8)},${mix(219, 48)},${mix(239, 107)})`;
}

// States on a circle; an arrow for each transition of non-zero probability,
// its width and colour by the probability and its value beside it; a loop
// for staying. A colour bar says what the colours mean.
function chainDrawing(stage) {
  const names = stateNames(stage);
  const m = chainMatrix(stage);
  const k = m.length;
  const NS = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(NS, "svg");
  svg.setAttribute("class", "chain");
  svg.setAttribute("viewBox", "0 0 460 330");
  svg.dataset.states = k;
  const el = (name, attrs, text, parent = svg) => {
    const e = document.createElementNS(NS, name);
    for (const [a, v] of Object.entries(attrs)) e.setAttribute(a, v);
    if (text !== undefined) e.textContent = text;
    parent.appendChild(e);
    return e;
  };
  const id = chainId++;
  const defs = el("defs", {});
  // Heads of one size whatever the arrow's width.
  const mk = el("marker", { id: `arrow-${id}`, viewBox: "0 0 10 10", refX: 9, refY: 5, markerWidth: 9, markerHeight: 9, orient: "auto-start-reverse", markerUnits: "userSpaceOnUse" }, undefined, defs);
  el("path", { d: "M0,0 L10,5 L0,10 z", fill: "#333" }, undefined, mk);
  const marker = `url(#arrow-${id})`;
  // On an ellipse, state 1 on the left; room around for the loops.
  const [cx, cy, Rx, Ry, r] = [230, 168, k === 1 ? 0 : 140, k === 1 ? 0 : 80, 30];
  const pos = names.map((_, i) => {
    const a = Math.PI + (2 * Math.PI * i) / k;
    return [cx + Rx * Math.cos(a), cy + Ry * Math.sin(a)];
  });
  for (let i = 0; i < k; i++) {
    for (let j = 0; j < k; j++) {
      const p = m[i][j];
      if (!(p > 0)) continue;
      const attrs = { class: i === j ? "edge self" : "edge", "data-from": i, "data-to": j, "data-p": p, "marker-end": marker,
        stroke: probColour(p), "stroke-width": (1 + 5 * p).toFixed(2), fill: "none" };
      let lx, ly;
      if (i === j) {
        // A loop on the side away from the centre.
        const [x, y] = pos[i];
        const a = k === 1 ? -Math.PI / 2 : Math.atan2(y - cy, x - cx);
        const at = (da, d) => [x + d * Math.cos(a + da), y + d * Math.sin(a + da)];
        const [sx, sy] = at(-0.5, r), [ex, ey] = at(0.5, r + 2);
        const [c1x, c1y] = at(-0.8, r + 42), [c2x, c2y] = at(0.8, r + 42);
        el("path", { ...attrs, d: `M${sx},${sy} C${c1x},${c1y} ${c2x},${c2y} ${ex},${ey}` });
        [lx, ly] = at(0, r + 44);
      } else {
        // Two arrows between a pair run side by side, each on its right.
        const [x1, y1] = pos[i], [x2, y2] = pos[j];
        const d = Math.hypot(x2 - x1, y2 - y1);
        const [ux, uy] = [(x2 - x1) / d, (y2 - y1) / d];
        const [ox, oy] = [-uy * 7, ux * 7];
        const [sx, sy] = [x1 + ux * r + ox, y1 + uy * r + oy];
        const [ex, ey] = [x2 - ux * (r + 2) + ox, y2 - uy * (r + 2) + oy];
        el("path", { ...attrs, d: `M${sx},${sy} L${ex},${ey}` });
        [lx, ly] = [(sx + ex) / 2 + ox * 1.8 + (ex - sx) * 0.12, (sy + ey) / 2 + oy * 1.8 + (ey - sy) * 0.12];
      }
      el("text", { x: lx, y: ly + 4, class: "p", "data-from": i, "data-to": j }, fmtP(p));
    }
  }
  names.forEach((s, i) => {
    el("circle", { cx: pos[i][0], cy: pos[i][1], r, class: "state" });
    // A name of two words on two lines.
    const [first, ...rest] = s.split(" ");
    const lines = rest.length ? [first, rest.join(" ")] : [s];
    lines.forEach((line, n) => el("text", { x: pos[i][0], y: pos[i][1] + 4 + (n - (lines.length - 1) / 2) * 12, class: "s" }, line.length > 12 ? line.slice(0, 11) + "…" : line));
  });
  // The colour scale.
  const grad = el("linearGradient", { id: `scale-${id}` }, undefined, defs);
  el("stop", { offset: "0", "stop-color": probColour(0) }, undefined, grad);
  el("stop", { offset: "1", "stop-color": probColour(1) }, undefined, grad);
  el("text", { x: 8, y: 14, class: "scale-label" }, "transition probability (wider: likelier)");
  el("rect", { class: "scale", x: 22, y: 20, width: 110, height: 8, fill: `url(#scale-${id})`, stroke: "#999" });
  el("text", { x: 10, y: 28, class: "scale-label" }, "0");
  el("text", { x: 136, y: 28, class: "scale-label" }, "1");
  return svg;
}

function fmtP(p) {
  return p >= 0.01 || p === 0 ? p.toFixed(3) : p.toExponential(1);
}

// ---- the burst law of a state: what α and λ realize ----

// P(b ≥ k) = (1 + k/λ)^(−α): the floored Lomax of ge_lomax.
function burstTail(alpha, lambda, k) {
  return Math.pow(1 + k / lambda, -alpha);
}

// E[b] = Σ_{k≥1} (1 + k/λ)^(−α); infinite for α ≤ 1. Summed to 10^5 terms,
// the rest by its integral.
function burstMean(alpha, lambda) {
  if (!(alpha > 1) || !(lambda > 0)) return Infinity;
  const K = 100000;
  let s = 0;
  for (let k = 1; k <= K; k++) s += burstTail(alpha, lambda, k);
  return s + (lambda / (alpha - 1)) * Math.pow(1 + (K + 0.5) / lambda, 1 - alpha);
}

// What one state's α and λ mean, in words.
function stateSaid(alpha, lambda) {
  const none = 1 - burstTail(alpha, lambda, 1);
  const mean = burstMean(alpha, lambda);
  const meanSaid = isFinite(mean) ? `${mean.toFixed(2)} frames` : "unbounded (α ≤ 1: in the long run every frame is dropped)";
  return `a burst drawn here drops ${meanSaid} on average; no frame at all with probability ${(100 * none).toFixed(1)} %; ` +
    `10 or more with ${(100 * burstTail(alpha, lambda, 10)).toFixed(2)} %`;
}

// ---- the matrix editor ----

// Sets row i's entry j to v and keeps the row at 1: the other entries
// scaled in proportion (`others`), or the stay probability (the diagonal)
// taking up the difference (`stay`; an edit of the diagonal then scales
// the others).
function rebalance(row, j, v, how) {
  const i = row.__i;
  v = Math.max(0, Math.min(1, Number(v) || 0));
  const n = row.length;
  const stayMode = how === "stay" && j !== i && n > 1;
  if (stayMode) {
    const offOthers = row.reduce((s, x, c) => (c === i || c === j ? s : s + x), 0);
    v = Math.min(v, 1 - offOthers);
    row[j] = v;
    row[i] = Math.max(0, 1 - offOthers - v);
  } else {
    const rest = row.reduce((s, x, c) => (c === j ? s : s + x), 0);
    row[j] = v;
    for (let c = 0; c < n; c++) {
      if (c === j) continue;
      row[c] = rest > 0 ? (row[c] * (1 - v)) / rest : n > 1 ? (1 - v) / (n - 1) : 0;
    }
    if (n === 1) row[0] = 1;
  }
  // Rounded to 6 places, the rounding put on the largest other entry.
  for (let c = 0; c < n; c++) row[c] = Math.round(row[c] * 1e6) / 1e6;
  const big = row.reduce((b, x, c) => (c !== j && x > row[b] ? c : b), j === 0 && n > 1 ? 1 : 0);
  row[big] = Math.round((row[big] + 1 - row.reduce((s, x) => s + x, 0)) * 1e6) / 1e6;
  return row;
}

// A state added: a new column of 0 in every row, a new row that stays
// with 0.9 and goes back to state 1 with 0.1; its burst law that of the
// last state.
function addState(stage) {
  const n = stage.transition.length;
  if (n >= MAX_STATES) return;
  const names = stateNames(stage).slice();
  stage.transition.forEach((row) => row.push(0));
  const row = new Array(n + 1).fill(0);
  row[0] = 0.1;
  row[n] = 0.9;
  stage.transition.push(row);
  stage.alpha.push(stage.alpha[n - 1]);
  stage.lambda.push(stage.lambda[n - 1]);
  stage._names = names.concat([STATE_NAMES[n]]);
}

// State s removed (not the first, which starts): what went to it stays.
function removeState(stage, s) {
  const n = stage.transition.length;
  if (n <= 1 || s === 0) return;
  const names = stateNames(stage).slice();
  stage.transition.forEach((row, i) => { row[i] += row[s]; row.splice(s, 1); });
  stage.transition.splice(s, 1);
  stage.alpha.splice(s, 1);
  stage.lambda.splice(s, 1);
  names.splice(s, 1);
  stage._names = names;
}

// The grid and the per-state laws of a ge_lomax stage `stage` (the page's
// stage number k); `changed()` after every edit that changes the file,
// `rebuilt()` after one that changes the grid's shape.
function matrixEditor(stage, k, changed, rebuilt) {
  const box = document.createElement("div");
  box.className = "matrix-editor";
  box.id = `matrix-${k}`;
  const names = stateNames(stage);
  const n = stage.transition.length;
  const how = document.createElement("select");
  how.id = `rebalance-${k}`;
  fill(how, [["others", "scaling the row's other entries"], ["stay", "adjusting the stay probability (the diagonal)"]]);
  how.value = stage._how || "others";
  how.onchange = () => { stage._how = how.value; };
  const note = document.createElement("p");
  note.className = "note";
  note.append("Transition probabilities from the row's state to the column's, per frame; state 1 starts. Each row sums to 1: an edit is balanced by ", how, ".");
  box.appendChild(note);
  const table = document.createElement("table");
  table.className = "matrix";
  const head = table.insertRow();
  head.appendChild(document.createElement("th")).textContent = "from \\ to";
  names.forEach((s) => { head.appendChild(document.createElement("th")).textContent = s; });
  head.appendChild(document.createElement("th")).textContent = "row sum";
  const sums = [];
  const drawing = { svg: null };
  const redraw = () => {
    stage.transition.forEach((row, i) => {
      row.forEach((v, j) => { const c = $(`tm-${k}-${i}-${j}`); if (c && document.activeElement !== c) c.value = v; });
      sums[i].textContent = row.reduce((s, x) => s + x, 0).toFixed(4);
    });
    const svg = chainDrawing(stage);
    drawing.svg.replaceWith(svg);
    drawing.svg = svg;
  };
  stage.transition.forEach((row, i) => {
    const tr = table.insertRow();
    const name = document.createElement("input");
    Object.assign(name, { value: names[i], size: 12, id: `state-name-${k}-${i}` });
    name.oninput = () => {
      stage._names[i] = name.value;
      const law = $(`state-law-name-${k}-${i}`);
      if (law) law.textContent = name.value;
      redraw();
    };
    tr.insertCell().appendChild(name);
    row.forEach((v, j) => {
      const cell = document.createElement("input");
      Object.assign(cell, { type: "number", min: 0, max: 1, step: 0.001, value: v, id: `tm-${k}-${i}-${j}` });
      cell.dataset.param = `transition.${i}.${j}`;
      cell.oninput = () => {
        if (cell.value === "") return;
        row.__i = i;
        rebalance(row, j, cell.value, how.value);
        delete row.__i;
        redraw();
        changed();
      };
      cell.onchange = () => { cell.value = row[j]; };
      tr.insertCell().appendChild(cell);
    });
    const sum = tr.insertCell();
    sum.className = "row-sum";
    sum.id = `row-sum-${k}-${i}`;
    sums.push(sum);
  });
  box.appendChild(table);
  const laws = stateLaws(stage, k, names, changed, rebuilt);
  box.appendChild(laws);
  drawing.svg = chainDrawing(stage);
  box.appendChild(drawing.svg);
  stage.transition.forEach((row, i) => { sums[i].textContent = row.reduce((s, x) => s + x, 0).toFixed(4); });
  box.redraw = redraw;
  return box;
}

// α and λ of each state, each said in words as it moves; a state added or
// removed.
function stateLaws(stage, k, names, changed, rebuilt) {
  const n = stage.transition.length;
  const laws = document.createElement("div");
  laws.className = "laws";
  const explain = document.createElement("p");
  explain.className = "note";
  explain.textContent = "In each state a burst of b dropped frames is drawn when the last one ended, then one frame is delivered: " +
    "P(b ≥ k) = (1 + k/λ)^−α. λ sets the burst's scale (in frames); α its tail: the smaller α, the likelier long bursts " +
    "(α ≤ 1: no finite mean, and in the long run every frame is dropped).";
  laws.appendChild(explain);
  for (let s = 0; s < n; s++) {
    const row = document.createElement("div");
    row.className = "param state-law";
    const label = document.createElement("span");
    label.className = "pname";
    label.textContent = names[s];
    label.id = `state-law-name-${k}-${s}`;
    const said = document.createElement("span");
    said.className = "said";
    said.id = `state-said-${k}-${s}`;
    const update = () => { said.textContent = stateSaid(Number(stage.alpha[s]), Number(stage.lambda[s])); };
    const param = (key, lo, hi) => {
      const wrap = document.createElement("label");
      wrap.append(` ${key === "alpha" ? "α" : "λ"} `);
      const range = document.createElement("input");
      Object.assign(range, { type: "range", min: lo, max: hi, step: 0.001, value: stage[key][s] });
      const num = document.createElement("input");
      Object.assign(num, { type: "number", min: 0, step: "any", value: stage[key][s], id: `${key}-${k}-${s}` });
      num.dataset.param = range.dataset.param = `${key}.${s}`;
      const set = (x) => { stage[key][s] = Number(x); update(); changed(); };
      range.oninput = () => { num.value = range.value; set(range.value); };
      num.oninput = () => { if (num.value !== "" && Number(num.value) > 0) { range.value = num.value; set(num.value); } };
      wrap.append(range, num);
      return wrap;
    };
    row.append(label, param("alpha", 0.1, Math.max(10, 2 * stage.alpha[s])), param("lambda", 0.01, Math.max(10, 2 * stage.lambda[s])));
    if (s > 0) {
      const rm = document.createElement("button");
      rm.textContent = "remove state";
      rm.className = "remove-state";
      rm.id = `remove-state-${k}-${s}`;
      rm.onclick = () => { removeState(stage, s); rebuilt(); };
      row.appendChild(rm);
    }
    row.appendChild(document.createElement("br"));
    row.appendChild(said);
    laws.appendChild(row);
    update();
  }
  const add = document.createElement("button");
  add.textContent = "add a state";
  add.id = `add-state-${k}`;
  add.disabled = n >= MAX_STATES;
  add.title = `at most ${MAX_STATES} states`;
  add.onclick = () => { addState(stage); rebuilt(); };
  laws.appendChild(add);
  return laws;
}
