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
  async act(url, extra) {
    $("study-action-error").textContent = "";
    try { await callJson("POST", url, Object.assign({ file: this.file(), participant: this.who() }, extra || {})); }
    catch (e) { $("study-action-error").textContent = e.message; }
    await this.refresh();
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
      running: `Trial ${n.trial} is running: ${n.condition}`,
      unmarked: `Trial ${n.trial} (${n.condition}) ran: mark it`,
      questionnaire: `Questionnaire due: ${n.questionnaire === "sus" ? "System Usability Scale" : "NASA-TLX after block " + n.block}`,
      finished: "Every trial is done.",
    }[n.kind];
    if (v.busy && !v.started_here) text += ` (busy: ${v.busy})`;
    $("next-text").textContent = text;
    $("next-text").dataset.kind = n.kind;
    $("start-btn").disabled = n.kind !== "trial";
    $("stop-btn").disabled = !(running && v.started_here);
    ["mark-done", "mark-failed", "mark-repeat"].forEach((b) => ($(b).disabled = n.kind !== "unmarked"));
    $("sus-box").hidden = n.questionnaire !== "sus";
    $("tlx-box").hidden = n.questionnaire !== "tlx";
    $("missing-box").hidden = n.kind !== "questionnaire";
    $("tlx-block").textContent = n.block ? `after block ${n.block}` : "";
    const rows = v.trials.map((t) => `<tr data-state="${t.state}"><td>${t.trial}</td><td>${esc(t.block)}</td><td>${esc(t.condition)}</td><td>${t.state}</td><td>${t.attempts}</td><td>${esc(t.note)}</td></tr>`);
    $("trials").innerHTML = "<tr><th>trial</th><th>block</th><th>condition</th><th>state</th><th>attempts</th><th>note</th></tr>" + rows.join("");
  },
};
function esc(s) { const d = document.createElement("div"); d.textContent = s ?? ""; return d.innerHTML; }
$("study-open").onclick = () => { location.href = `/study?file=${encodeURIComponent(study.file())}`; };
if ($("participant")) {
  $("participant").onchange = () => study.refresh();
  $("start-btn").onclick = () => study.act("/api/study/start");
  $("stop-btn").onclick = () => study.act("/api/study/stop");
  for (const how of ["done", "failed", "repeat"]) $(`mark-${how}`).onclick = () => study.act("/api/study/mark", { how, note: $("mark-note").value });
  $("sus-submit").onclick = () => study.act("/api/study/answer", { instrument: "sus", values: [...document.querySelectorAll(".sus-item")].map((s) => Number(s.value)) });
  $("tlx-submit").onclick = () => study.act("/api/study/answer", { instrument: "tlx", values: [...document.querySelectorAll(".tlx-scale")].map((s) => Number(s.value)) });
  $("missing-submit").onclick = () => {
    const kind = $("sus-box").hidden ? "tlx" : "sus";
    study.act("/api/study/answer", { instrument: kind, missing: $("missing-reason").value });
  };
  document.querySelectorAll(".tlx-scale").forEach((r) => { r.oninput = () => (r.nextElementSibling.textContent = r.value); r.oninput(); });
  study.refresh();
  setInterval(() => study.refresh(), 500);
}
