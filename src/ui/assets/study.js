// netfi ui: the study page (after call.js).

// The answer of `call`, as JSON (null when empty).
async function callJson(method, url, body) {
  const text = await call(method, url, body);
  return text ? JSON.parse(text) : null;
}
const study = {
  file() { return $("study-path").value; },
  who() { return $("participant") ? $("participant").value : ""; },
  q() { return `file=${encodeURIComponent(this.file())}&participant=${encodeURIComponent(this.who())}`; },
  // Posts an action; true when the server took it.
  async act(url, extra) {
    $("study-action-error").textContent = "";
    let ok = true;
    try { await callJson("POST", url, Object.assign({ file: this.file(), participant: this.who() }, extra || {})); }
    catch (e) { $("study-action-error").textContent = e.message; ok = false; }
    await this.refresh();
    return ok;
  },
  async refresh() {
    if (!this.who()) { ["next-box", "sus-box", "tlx-box", "missing-box", "trials-box"].forEach((b) => ($(b).hidden = true)); return; }
    let v;
    try { v = await callJson("GET", `/api/study/status?${this.q()}`); }
    catch (e) { $("study-action-error").textContent = e.message; return; }
    $("participant-view").href = `/study/view?${this.q()}`;
    $("next-box").hidden = false;
    $("trials-box").hidden = false;
    const n = v.next;
    const running = n.kind === "running";
    let text = {
      trial: `Trial ${n.trial} (attempt ${n.attempt}): ${n.condition}, block ${n.block}`,
      running: `Trial ${n.trial} is running: ${n.condition}${n.waiting_for ? `; waiting for ${n.waiting_for}` : ""}`,
      unmarked: `Trial ${n.trial} (${n.condition}) ran: mark it`,
      questionnaire: `Questionnaire due: ${n.title}`,
      finished: "Every trial is done.",
    }[n.kind];
    if (v.busy && !v.started_here) text += ` (busy: ${v.busy})`;
    $("next-text").textContent = text;
    $("next-text").dataset.kind = n.kind;
    $("start-btn").disabled = n.kind !== "trial";
    // A trial started elsewhere (a terminal) is stopped through its runner.
    $("stop-btn").disabled = !running;
    ["mark-done", "mark-failed", "mark-repeat"].forEach((b) => ($(b).disabled = n.kind !== "unmarked"));
    // A form shown for another questionnaire than before starts blank.
    for (const [box, q] of [["sus-box", "sus"], ["tlx-box", "tlx"]]) {
      const shown = n.questionnaire === q;
      if (shown && $(box).dataset.key !== n.key) forms.clear(box);
      $(box).dataset.key = shown ? n.key : "";
      $(box).hidden = !shown;
    }
    if (n.title) $(n.questionnaire === "sus" ? "sus-title" : "tlx-title").textContent = n.title;
    $("missing-box").hidden = n.kind !== "questionnaire";
    const changed = v.study_changed || [];
    $("study-changed").hidden = changed.length === 0;
    $("study-changed").innerHTML = changed.map((c) => `<li>${esc(c)}</li>`).join("");
    const report = (t) => (t.run_id && !["pending", "running", "interrupted"].includes(t.state) ? `<a href="/runs/${encodeURIComponent(t.run_id)}/report">report</a>` : "");
    const counts = (t) => Object.entries(t.counts || {}).map(([k, c]) => `${esc(k)} ${c}`).join(", ");
    const rows = v.trials.map((t) => `<tr data-state="${t.state}"><td>${t.trial}</td><td>${esc(t.block)}</td><td>${esc(t.condition)}</td><td>${t.state}${t.stopped ? " (stopped)" : ""}${t.clean === "suspect" ? ` <span class="suspect">(suspect)</span>` : ""}</td><td>${t.attempts}</td><td>${counts(t)}</td><td>${esc(t.note)}${t.clean === "suspect" ? `<br><small>${esc((t.suspect_because || []).join("; "))}</small>` : ""}</td><td>${report(t)}</td></tr>`);
    $("trials").innerHTML = "<tr><th>trial</th><th>block</th><th>condition</th><th>state</th><th>attempts</th><th>counts</th><th>note</th><th></th></tr>" + rows.join("");
  },
};
// The questionnaires: nothing is chosen beforehand, and a form is sent
// only once every item is answered (the server refuses it otherwise too).
const forms = {
  // The chosen value of each radio group `prefix-i` (null: untouched).
  chosen(prefix, n) {
    return [...Array(n).keys()].map((i) => {
      const r = document.querySelector(`input[name="${prefix}-${i}"]:checked`);
      return r ? Number(r.value) : null;
    });
  },
  sus() { return this.chosen("sus", 11).slice(1); },
  tlx() { return this.chosen("tlx", 6); },
  pairs() { return $("tlx-pairs") ? this.chosen("pair", 15) : null; },
  clear(box) { $(box).querySelectorAll("input[type=radio]").forEach((r) => (r.checked = false)); this.check(); },
  // Enables a form's button once every item is answered; names the others.
  check() {
    const open = (vals, name) => vals.map((v, i) => (v === null ? name(i) : null)).filter((x) => x !== null);
    const sus = open(this.sus(), (i) => i + 1);
    $("sus-submit").disabled = sus.length > 0;
    $("sus-unanswered").textContent = sus.length ? `not answered yet: statement ${sus.join(", ")}` : "";
    const tlx = open(this.tlx(), (i) => document.querySelectorAll(".tlx-scale")[i].dataset.scale.replace("_", " "));
    const pairs = this.pairs() ? open(this.pairs(), (i) => `pair ${i + 1}`) : [];
    $("tlx-submit").disabled = tlx.length + pairs.length > 0;
    $("tlx-unanswered").textContent = tlx.length + pairs.length ? `not answered yet: ${tlx.concat(pairs).join(", ")}` : "";
  },
};
function esc(s) { const d = document.createElement("div"); d.textContent = s ?? ""; return d.innerHTML; }
$("study-open").onclick = () => { location.href = `/study?file=${encodeURIComponent(study.file())}`; };
if ($("participant")) {
  $("participant").onchange = () => study.refresh();
  $("start-btn").onclick = () => study.act("/api/study/start");
  $("stop-btn").onclick = () => study.act("/api/study/stop");
  for (const how of ["done", "failed", "repeat"]) {
    $(`mark-${how}`).onclick = async () => {
      const counts = {};
      document.querySelectorAll(".measure").forEach((m) => { if (m.value !== "") counts[m.dataset.name] = Number(m.value); });
      // The note and counts belong to this trial: cleared once it is marked.
      if (await study.act("/api/study/mark", { how, note: $("mark-note").value, counts })) {
        $("mark-note").value = "";
        document.querySelectorAll(".measure").forEach((m) => (m.value = ""));
      }
    };
  }
  $("sus-submit").onclick = async () => { if (await study.act("/api/study/answer", { instrument: "sus", values: forms.sus() })) forms.clear("sus-box"); };
  $("tlx-submit").onclick = async () => {
    const body = { instrument: "tlx", values: forms.tlx() };
    if (forms.pairs()) body.pairs = forms.pairs();
    if (await study.act("/api/study/answer", body)) forms.clear("tlx-box");
  };
  $("missing-submit").onclick = async () => {
    const kind = $("sus-box").hidden ? "tlx" : "sus";
    if (await study.act("/api/study/answer", { instrument: kind, missing: $("missing-reason").value })) $("missing-reason").value = "";
  };
  document.querySelectorAll(".form input[type=radio]").forEach((r) => (r.onchange = () => forms.check()));
  forms.check();
  study.refresh();
  setInterval(() => study.refresh(), 500);
}
