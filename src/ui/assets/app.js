// netfi ui: the scenario builder and a run's page (after call.js).

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
    $("new-scenario").onclick = () => this.fresh();
    // The scenario being built lives in the tab's session: a visit to the
    // runs, a run's page or a reload finds it as it was left.
    const kept = sessionStorage.getItem(KEPT);
    if (kept) {
      $("toml").value = kept;
      this.load(kept);
    } else {
      this.fresh();
    }
  },

  // The example: one four-parameter ge_lomax stage.
  fresh() {
    $("scenario-name").value = "my scenario";
    $("scenario-seed").value = "1";
    this.timeline = false;
    this.stages = [];
    this.add(structuredClone(this.catalogue.models.find((m) => m.name === "ge_lomax").stage));
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
    const grid = stage.model === "ge_lomax" && Array.isArray(stage.transition);
    for (const [key, value] of Object.entries(stage)) {
      if (key === "model" || key === "preset" || key.startsWith("_")) continue;
      if (grid && ["transition", "alpha", "lambda"].includes(key)) continue;
      fs.appendChild(this.field(stage, key, value, [key]));
    }
    if (grid) {
      fs.appendChild(matrixEditor(stage, i + 1, () => this.write(), () => this.render()));
    } else if (isChain(stage)) {
      const svg = chainDrawing(stage);
      fs.appendChild(svg);
      fs.redraw = () => { const next = chainDrawing(stage); fs.querySelector("svg.chain").replaceWith(next); };
    }
    // What the stage alone realizes, beside its parameters.
    if (BRIEF_MODELS.includes(stage.model)) {
      const brief = document.createElement("div");
      brief.className = "stage-brief";
      brief.id = `stage-brief-${i + 1}`;
      fs.appendChild(brief);
    }
    return fs;
  },

  // Each loss stage's own figures, simulated alone, a moment after the
  // last change.
  briefs() {
    clearTimeout(this.briefTimer);
    this.briefTimer = setTimeout(() => {
      this.stages.forEach((stage, i) => {
        if (!BRIEF_MODELS.includes(stage.model)) return;
        const box = $(`stage-brief-${i + 1}`);
        if (!box) return;
        const text = `name = "stage ${i + 1}"\nseed = ${Number($("scenario-seed").value) || 1}\n\n[[stage]]\n` + stageToml(stage);
        const req = { toml: text, frames: BRIEF_FRAMES, rate_hz: Number($("preview-rate").value) || 1000, stage: i + 1 };
        const asked = (box.asked = (box.asked || 0) + 1);
        call("POST", "/api/preview", req)
          .then((html) => { if (box.asked === asked) box.innerHTML = html; })
          .catch((e) => { if (box.asked === asked) box.innerHTML = `<p class="error">${escapeHtml(e.message)}</p>`; });
      });
    }, 250);
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
    const set = (x) => {
      setAt(stage, path, Number(x));
      this.write();
      range.closest("fieldset.stage")?.redraw?.();
    };
    range.oninput = () => { num.value = range.value; set(range.value); };
    num.oninput = () => { range.value = num.value; set(num.value); };
    wrap.append(range, num);
    return wrap;
  },

  toml() {
    const lines = [`name = ${JSON.stringify($("scenario-name").value || "scenario")}`];
    const seed = $("scenario-seed").value;
    if (seed !== "") lines.push(`seed = ${Number(seed)}`);
    for (const st of this.stages) lines.push("", "[[stage]]", stageToml(st).trimEnd());
    return lines.join("\n") + "\n";
  },

  // The text from the stages, kept in the session; the previews again.
  write() {
    if (!this.timeline) $("toml").value = this.toml();
    $("toml-error").textContent = "";
    this.changed();
  },

  changed() {
    sessionStorage.setItem(KEPT, $("toml").value);
    this.briefs();
    if ($("preview-auto").checked) {
      clearTimeout(this.previewTimer);
      this.previewTimer = setTimeout(() => this.preview(), 600);
    }
  },

  // TOML into the builder: through the server's parser, so its errors are
  // the file's. A timeline (phases) stays as text: the builder edits one
  // pipeline.
  async load(text) {
    try {
      const v = JSON.parse(await call("POST", "/api/parse", { toml: text }));
      $("scenario-name").value = v.name || "scenario";
      $("scenario-seed").value = v.seed ?? "";
      this.timeline = !!v.phase;
      $("timeline-note").hidden = !this.timeline;
      if (this.timeline) {
        $("timeline-note").textContent = `a timeline of ${v.phase.length} phases: kept as text (the builder edits one pipeline); the preview and the run use it as written`;
        this.stages = [];
        $("stages").replaceChildren();
        $("toml").value = text;
        $("toml-error").textContent = "";
        this.changed();
        return;
      }
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
    const asked = (this.previewAsked = (this.previewAsked || 0) + 1);
    $("preview").innerHTML = "<p class=busy>simulating…</p>";
    try {
      const html = await call("POST", "/api/preview", req);
      if (asked === this.previewAsked) $("preview").innerHTML = html;
    } catch (e) {
      if (asked !== this.previewAsked) return;
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
      const num = (id) => ($(id).value.trim() === "" ? null : Number($(id).value));
      const req = {
        toml: $("toml").value, duration_s, seed,
        rate_hz: num("run-rate"),
        return_scenario: $("run-return").value || null,
        video_mbps: num("run-video"),
        video_scenario: $("run-video-scenario").value || null,
        capture: $("run-capture").value.trim() || null,
        isolate: $("run-isolate").checked,
      };
      const r = JSON.parse(await call("POST", "/api/runs", req));
      location.href = `/runs/${r.id}`;
    } catch (e) {
      $("run-error").textContent = e.message;
    }
  },
};

// Where the tab keeps the scenario being built.
const KEPT = "netfi-scenario";
// The stages whose own figures the builder shows beside them.
const BRIEF_MODELS = ["ge_lomax", "markov4", "gilbert_elliott", "bernoulli"];
const BRIEF_FRAMES = 50000;

// One stage's lines of TOML (the page's own keys, `_…`, left out).
function stageToml(st) {
  return Object.entries(st).filter(([k]) => !k.startsWith("_")).map(([k, v]) => `${k} = ${tomlValue(v)}\n`).join("");
}

function escapeHtml(t) {
  return t.replace(/[&<>"]/g, (c) => ({ "&": "&amp;", "<": "&lt;", ">": "&gt;", '"': "&quot;" })[c]);
}

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

// ---- a run's page -----------------------------------------------------------

const CONTROLS = ["switch-to", "switch-at", "switch-btn", "phase-to", "phase-at", "phase-btn", "pause-btn", "resume-btn", "stop-btn"];

const runPage = {
  id: null,
  timer: null,
  ended: false,

  init() {
    this.id = $("run-id").textContent;
    $("stop-btn").onclick = () => {
      $("stop-btn").disabled = true;
      $("control-note").textContent = "stopping: the run ends its processes and writes its report…";
      call("POST", `/api/runs/${this.id}/stop`, {}).catch((e) => this.error(e));
    };
    // The scenario being built, when this tab holds one.
    const built = sessionStorage.getItem(KEPT);
    if (built) {
      $("switch-built").disabled = false;
      const name = /^name\s*=\s*"([^"]*)"/m.exec(built);
      $("switch-built").textContent = `the scenario being built${name ? ` (${name[1]})` : ""}`;
    }
    $("switch-btn").onclick = () => {
      const to = $("switch-to").value;
      const at = $("switch-at").value.trim() || null;
      this.ctl(to === "@built" ? { cmd: "switch", toml: sessionStorage.getItem(KEPT) || "", at } : { cmd: "switch", preset: to, at });
    };
    $("phase-btn").onclick = () => this.ctl({ cmd: "phase", phase: $("phase-to").value, at: $("phase-at").value.trim() || null });
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
      if (r.state) this.state(r.state);
    } catch (e) {
      this.error(e);
    }
  },

  event(ev) {
    const li = document.createElement("li");
    li.textContent = `${ev.t_s.toFixed(3)} s: ${ev.what}`;
    $("events").appendChild(li);
  },

  // The emulator's state: where the run is, and the phases it can go to.
  state(st) {
    const phase = st.phase_name ? `${st.phase} (${st.phase_name})` : `${st.phase}`;
    const next = (st.upcoming || []).map(([t, name, p]) => `${name} phase ${p} at ${t.toFixed(3)} s`).join("; ");
    $("ctl-now").textContent = `t = ${st.t_s.toFixed(3)} s, ${st.scenario} (the run's phase ${phase}), faults ${st.paused ? "paused" : "on"}` +
      (next ? `; next: ${next}` : "");
    // Pause when on, resume when paused.
    if (!this.ended) {
      $("pause-btn").disabled = !!st.paused;
      $("resume-btn").disabled = !st.paused;
    }
    const phases = st.scenario_phases || [];
    const sel = $("phase-to");
    const want = phases.map((p) => [String(p.number), `${p.number}${p.name ? " " + p.name : ""} (from ${p.start_s} s of ${st.scenario})`]);
    if (sel.options.length !== want.length || [...sel.options].some((o, k) => o.textContent !== want[k][1])) fill(sel, want);
  },

  // Once the run has ended nothing steers it: the controls say so.
  disable(said) {
    this.ended = true;
    CONTROLS.forEach((id) => { $(id).disabled = true; });
    $("control-note").textContent = said;
  },

  async poll() {
    let s;
    try {
      s = JSON.parse(await call("GET", `/api/runs/${this.id}`));
    } catch (e) {
      return this.error(e);
    }
    $("run-state").textContent = s.state;
    $("run-state").className = `state ${s.state}`;
    $("run-said").textContent = s.state_said;
    $("run-elapsed").textContent = s.state === "running" ? ` · ${s.elapsed_s.toFixed(1)} s of ${s.duration_s} s` : "";
    if (s.live) $("live-table").innerHTML = s.live;
    if (s.state === "running") {
      // Where the emulator is, every 2 s (quietly: its control service
      // may not be up yet).
      if ((this.polls = (this.polls || 0) + 1) % 4 === 1) {
        call("POST", `/api/runs/${this.id}/ctl`, { cmd: "show" }).then((t) => this.state(JSON.parse(t).state)).catch(() => {});
      }
      return;
    }
    clearInterval(this.timer);
    this.disable(`The run has ended (${s.state}): live control steers a running run only.`);
    $("done").hidden = false;
    const r = s.report || {};
    $("run-loss").textContent = r.loss_rate == null ? "-" : r.loss_rate.toFixed(4);
    $("run-faults").replaceChildren(...(r.faults || []).map((f) => { const li = document.createElement("li"); li.textContent = f; return li; }));
    $("run-phases").innerHTML = phasesTable(r.phases || []);
    $("run-stderr").textContent = s.stderr_tail || "";
    $("report-link").hidden = !s.report;
    if (r.events) {
      $("events").replaceChildren();
      r.events.forEach((ev) => this.event(ev));
    }
  },
};

// A run's stretches under one condition, as a table.
function phasesTable(phases) {
  if (!phases.length) return "";
  const rows = phases.map((p) => {
    const span = `${(p.from_ns / 1e9).toFixed(3)}–${p.to_ns == null ? "end" : (p.to_ns / 1e9).toFixed(3)} s`;
    const what = p.paused ? "faults paused" : `${p.scenario} phase ${p.scenario_phase}${p.phase_name ? " " + p.phase_name : ""}`;
    const model = p.loss_rate_model == null ? "-" : p.loss_rate_model.toFixed(4);
    return `<tr class="phase"><td>${span}</td><td>${escapeHtml(what)}</td><td>${p.frames}</td><td>${p.dropped}</td>` +
      `<td class="loss">${p.loss_rate.toFixed(4)} [${p.loss_rate_ci95[0].toFixed(4)}, ${p.loss_rate_ci95[1].toFixed(4)}]</td><td>${model}</td></tr>`;
  });
  return `<table id="run-phase-table" class="figures"><tr><th>when</th><th>condition</th><th>frames</th><th>dropped</th>` +
    `<th>loss [95%]</th><th>model's loss</th></tr>${rows.join("")}</table>`;
}

// ---- the list of runs ---------------------------------------------------------

function runsPage() {
  for (const td of document.querySelectorAll("td.started")) {
    const t = new Date(Number(td.dataset.unix) * 1000);
    td.textContent = t.toLocaleString();
  }
}

document.addEventListener("DOMContentLoaded", () => {
  const page = document.body.dataset.page;
  if (page === "builder") builder.init();
  if (page === "run") runPage.init();
  if (page === "runs") runsPage();
});
