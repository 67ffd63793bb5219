// netfi ui: the scenario builder and a run's page. Plain script, compiled
// into the binary with the page; it talks only to the server that sent it.
"use strict";

const $ = (id) => document.getElementById(id);

// Every state change is JSON with the page's own header: the server
// refuses anything else, so no other page can make one.
async function call(method, url, body) {
  const init = { method, headers: {}, credentials: "same-origin" };
  if (method !== "GET") {
    init.body = JSON.stringify(body ?? {});
    init.headers["content-type"] = "application/json";
    init.headers["x-netfi-ui"] = "1";
  }
  const res = await fetch(url, init);
  const text = await res.text();
  if (!res.ok) throw new Error(text || res.statusText);
  return text;
}

// ---- the builder ----------------------------------------------------------

const builder = {
  catalogue: null,
  stages: [],

  init() {
    this.catalogue = JSON.parse($("catalogue").textContent);
    const c = this.catalogue;
    fill($("add-model"), c.models.map((m) => [m.name, m.name]));
    fill($("add-preset"), c.presets.map((p) => [p.name, `${p.name} — ${p.label}`]));
    fill($("add-target"), c.targets.map((t) => [t.field, t.label]));
    $("add-target").onchange = () => this.targetDefault();
    this.targetDefault();
    $("add-model-btn").onclick = () => {
      const m = c.models.find((m) => m.name === $("add-model").value);
      this.add(structuredClone(m.stage));
    };
    $("add-preset-btn").onclick = () => this.add({ preset: $("add-preset").value });
    $("add-target-btn").onclick = () => this.add({ [$("add-target").value]: Number($("add-target-value").value) });
    $("scenario-name").oninput = $("scenario-seed").oninput = () => this.write();
    $("apply-text").onclick = () => this.load($("toml").value);
    $("load").onchange = (ev) => this.loadFile(ev.target.files[0]);
    $("save").onclick = () => this.save();
    $("preview-btn").onclick = () => this.preview();
    $("run-btn").onclick = () => this.run();
    this.add(structuredClone(c.models.find((m) => m.name === "ge_lomax").stage));
  },

  targetDefault() {
    const t = this.catalogue.targets.find((t) => t.field === $("add-target").value);
    $("add-target-value").value = t.value;
  },

  add(stage) {
    this.stages.push(stage);
    this.render();
  },

  render() {
    const box = $("stages");
    box.replaceChildren();
    this.stages.forEach((stage, i) => box.appendChild(this.stageBox(stage, i)));
    this.write();
  },

  stageBox(stage, i) {
    const fs = document.createElement("fieldset");
    fs.className = "stage";
    const legend = document.createElement("legend");
    legend.textContent = `stage ${i + 1}: ${stage.model || (stage.preset ? "preset " + stage.preset : "target")}`;
    const rm = document.createElement("button");
    rm.textContent = "remove";
    rm.className = "remove";
    rm.onclick = () => { this.stages.splice(i, 1); this.render(); };
    legend.appendChild(rm);
    fs.appendChild(legend);
    for (const [key, value] of Object.entries(stage)) {
      if (key === "model" || key === "preset") continue;
      fs.appendChild(this.field(stage, key, value, [key]));
    }
    if (isChain(stage)) fs.appendChild(chainDrawing(stage));
    return fs;
  },

  // One parameter: a list for a choice, sliders for numbers (one per entry
  // of a vector or matrix).
  field(stage, key, value, path) {
    const row = document.createElement("div");
    row.className = "param";
    const name = document.createElement("span");
    name.className = "pname";
    name.textContent = path.join(".");
    row.appendChild(name);
    const choices = this.catalogue.choices[key];
    if (choices && typeof value === "string") {
      const sel = document.createElement("select");
      fill(sel, choices.map((c) => [c, c]));
      sel.value = value;
      sel.dataset.param = path.join(".");
      sel.onchange = () => { setAt(stage, path, sel.value); this.write(); };
      row.appendChild(sel);
    } else if (Array.isArray(value)) {
      value.forEach((v, j) => row.appendChild(this.field(stage, key, v, path.concat([j]))));
    } else {
      row.appendChild(this.slider(stage, key, Number(asNumber(value)), path));
    }
    return row;
  },

  slider(stage, key, v, path) {
    const prob = this.catalogue.probability_fields.includes(key);
    const max = prob ? 1 : Math.max(10, niceUp(4 * v));
    const step = prob ? 0.0001 : (Number.isInteger(v) && !key.endsWith("_ms") ? 1 : max / 10000);
    const wrap = document.createElement("span");
    const range = document.createElement("input");
    Object.assign(range, { type: "range", min: 0, max, step, value: v });
    const num = document.createElement("input");
    Object.assign(num, { type: "number", min: 0, step: "any", value: v });
    num.dataset.param = range.dataset.param = path.join(".");
    const set = (x) => { setAt(stage, path, Number(x)); this.write(); };
    range.oninput = () => { num.value = range.value; set(range.value); };
    num.oninput = () => { range.value = num.value; set(num.value); };
    wrap.append(range, num);
    return wrap;
  },

  toml() {
    const lines = [`name = ${JSON.stringify($("scenario-name").value || "scenario")}`];
    const seed = $("scenario-seed").value;
    if (seed !== "") lines.push(`seed = ${Number(seed)}`);
    for (const st of this.stages) {
      lines.push("", "[[stage]]");
      for (const [k, v] of Object.entries(st)) lines.push(`${k} = ${tomlValue(v)}`);
    }
    return lines.join("\n") + "\n";
  },

  write() {
    $("toml").value = this.toml();
    $("toml-error").textContent = "";
  },

  // TOML into the builder: through the server's parser, so its errors are
  // the file's. A timeline (phases) stays as text: the builder edits one
  // pipeline.
  async load(text) {
    try {
      const v = JSON.parse(await call("POST", "/api/parse", { toml: text }));
      if (v.phase) {
        $("toml-error").textContent = "a timeline (phases): kept as text; preview and run use it as written";
        return;
      }
      $("scenario-name").value = v.name || "scenario";
      $("scenario-seed").value = v.seed ?? "";
      this.stages = v.stage || [];
      this.render();
    } catch (e) {
      $("toml-error").textContent = e.message;
    }
  },

  loadFile(file) {
    if (!file) return;
    file.text().then((t) => { $("toml").value = t; this.load(t); });
  },

  save() {
    const blob = new Blob([$("toml").value], { type: "application/toml" });
    const a = document.createElement("a");
    a.href = URL.createObjectURL(blob);
    a.download = ($("scenario-name").value || "scenario").replace(/[^A-Za-z0-9_-]+/g, "_") + ".toml";
    a.click();
    URL.revokeObjectURL(a.href);
  },

  async preview() {
    const req = { toml: $("toml").value, frames: Number($("preview-frames").value), rate_hz: Number($("preview-rate").value) };
    $("preview").innerHTML = "<p class=busy>simulating…</p>";
    try {
      $("preview").innerHTML = await call("POST", "/api/preview", req);
    } catch (e) {
      $("preview").innerHTML = "";
      const pre = document.createElement("pre");
      pre.className = "error";
      pre.id = "preview-error";
      pre.textContent = e.message;
      $("preview").appendChild(pre);
    }
  },

  async run() {
    $("run-error").textContent = "";
    try {
      const duration_s = parseDuration($("duration").value);
      const seed = $("scenario-seed").value === "" ? null : Number($("scenario-seed").value);
      const r = JSON.parse(await call("POST", "/api/runs", { toml: $("toml").value, duration_s, seed }));
      location.href = `/runs/${r.id}`;
    } catch (e) {
      $("run-error").textContent = e.message;
    }
  },
};

function fill(select, options) {
  select.replaceChildren(...options.map(([value, label]) => {
    const o = document.createElement("option");
    o.value = value;
    o.textContent = label;
    return o;
  }));
}

function asNumber(v) {
  return typeof v === "string" && v.trim().endsWith("%") ? parseFloat(v) / 100 : v;
}

function setAt(obj, path, value) {
  let o = obj;
  for (const k of path.slice(0, -1)) o = o[k];
  o[path[path.length - 1]] = value;
}

function niceUp(x) {
  if (!(x > 0)) return 1;
  const d = Math.pow(10, Math.floor(Math.log10(x)));
  return [1, 2, 5, 10].map((m) => m * d).find((v) => v >= x);
}

function tomlValue(v) {
  if (Array.isArray(v)) return `[${v.map(tomlValue).join(", ")}]`;
  if (typeof v === "string") return JSON.stringify(v);
  return String(v);
}

// "250ms", "10s", "2min", or a bare number of seconds.
function parseDuration(text) {
  const m = /^\s*([0-9.eE+-]+)\s*(ms|s|min|h)?\s*$/.exec(text);
  if (!m || !(Number(m[1]) >= 0)) throw new Error(`"${text}" is not a duration: e.g. 10s, 250ms, 2min`);
  return Number(m[1]) * { ms: 1e-3, s: 1, min: 60, h: 3600 }[m[2] || "s"];
}

// ---- a drawing of a loss model's chain ----------------------------------------

function isChain(stage) {
  return ["ge_lomax", "markov4", "gilbert_elliott"].includes(stage.model);
}

// States on a circle, an arrow per transition with its probability.
function chainDrawing(stage) {
  const { states, edges } = chainOf(stage);
  const ns = "http://www.w3.org/2000/svg";
  const svg = document.createElementNS(ns, "svg");
  svg.setAttribute("class", "chain");
  svg.setAttribute("viewBox", "0 0 320 200");
  const pos = states.map((_, i) => {
    const a = Math.PI + (2 * Math.PI * i) / states.length;
    return [160 + 110 * Math.cos(a), 100 + 65 * Math.sin(a)];
  });
  const el = (name, attrs, text) => {
    const e = document.createElementNS(ns, name);
    for (const [k, v] of Object.entries(attrs)) e.setAttribute(k, v);
    if (text !== undefined) e.textContent = text;
    svg.appendChild(e);
    return e;
  };
  edges.forEach(([from, to, p]) => {
    const [x1, y1] = pos[from], [x2, y2] = pos[to];
    const bend = 18;
    const mx = (x1 + x2) / 2 - ((y2 - y1) / Math.hypot(x2 - x1, y2 - y1)) * bend;
    const my = (y1 + y2) / 2 + ((x2 - x1) / Math.hypot(x2 - x1, y2 - y1)) * bend;
    el("path", { d: `M${x1},${y1} Q${mx},${my} ${x2},${y2}`, class: "edge" });
    el("text", { x: mx, y: my, class: "p" }, fmtP(p));
  });
  states.forEach((s, i) => {
    el("circle", { cx: pos[i][0], cy: pos[i][1], r: 20, class: "state" });
    el("text", { x: pos[i][0], y: pos[i][1] + 4, class: "s" }, s);
  });
  return svg;
}

function chainOf(st) {
  const n = (v) => Number(asNumber(v));
  if (st.model === "ge_lomax") {
    const t = st.transition;
    return { states: ["good", "bad"], edges: [[0, 1, t[0][1]], [1, 0, t[1][0]]] };
  }
  if (st.model === "gilbert_elliott") {
    return { states: ["good", "bad"], edges: [[0, 1, n(st.p)], [1, 0, n(st.r)]] };
  }
  return {
    states: ["1", "2", "3", "4"],
    edges: [[0, 2, n(st.p13)], [2, 0, n(st.p31)], [2, 1, n(st.p32)], [1, 2, n(st.p23)], [0, 3, n(st.p14)], [3, 0, 1]],
  };
}

function fmtP(p) {
  return p >= 0.01 ? p.toFixed(3) : p.toExponential(1);
}

// ---- a run's page -----------------------------------------------------------

const runPage = {
  id: null,
  timer: null,

  init() {
    this.id = $("run-id").textContent;
    $("stop-btn").onclick = () => call("POST", `/api/runs/${this.id}/stop`, {}).catch((e) => this.error(e));
    $("switch-btn").onclick = () => this.ctl({ cmd: "switch", arg: $("switch-to").value });
    $("pause-btn").onclick = () => this.ctl({ cmd: "pause" });
    $("resume-btn").onclick = () => this.ctl({ cmd: "resume" });
    this.poll();
    this.timer = setInterval(() => this.poll(), 500);
  },

  error(e) {
    $("ctl-error").textContent = e.message;
  },

  async ctl(req) {
    $("ctl-error").textContent = "";
    try {
      const r = JSON.parse(await call("POST", `/api/runs/${this.id}/ctl`, req));
      if (r.event) this.event(r.event);
    } catch (e) {
      this.error(e);
    }
  },

  event(ev) {
    const li = document.createElement("li");
    li.textContent = `${ev.t_s.toFixed(3)} s: ${ev.what}`;
    $("events").appendChild(li);
  },

  async poll() {
    let s;
    try {
      s = JSON.parse(await call("GET", `/api/runs/${this.id}`));
    } catch (e) {
      return this.error(e);
    }
    $("run-state").textContent = s.state;
    $("run-elapsed").textContent = `${s.elapsed_s.toFixed(1)} s of ${s.duration_s} s`;
    if (s.live) $("live-table").innerHTML = s.live;
    if (s.state === "running") return;
    clearInterval(this.timer);
    $("done").hidden = false;
    const loss = s.report && s.report.loss_rate;
    $("run-loss").textContent = loss == null ? "-" : loss.toFixed(4);
    $("run-stderr").textContent = s.state === "failed" ? s.stderr_tail || "" : "";
    if (s.report && s.report.events) {
      $("events").replaceChildren();
      s.report.events.forEach((ev) => this.event(ev));
    }
  },
};

document.addEventListener("DOMContentLoaded", () => {
  const page = document.body.dataset.page;
  if (page === "builder") builder.init();
  if (page === "run") runPage.init();
});
