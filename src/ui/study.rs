//! The experimenter's page (`/study?file=STUDY.toml`): choose a
//! participant, see their next trial, start and stop it, mark it, and
//! record the questionnaires the study asks for; and the participant's own
//! view (`/study/view?file=…&participant=…`), which names the condition
//! only when the study file allows it.
//!
//! A trial is a `netfi study next` child process, exactly as from the
//! command line: it takes the participant's lock, records the attempt and
//! runs `netfi run`; the page's stop is its Ctrl-C. The server holds no
//! study state of its own beyond those children: what the page shows is
//! read from the data folder at each request, so a trial started from a
//! terminal shows here too, and a second experimenter is refused by the
//! participant's lock. The child is told to stop if the server ends
//! (`PR_SET_PDEATHSIG`), so no trial outlives the page that started it.

use crate::study::file::TlxWeighting;
use crate::study::questionnaire::{self, tlx_pairs, Instrument, SUS_SCALE, SUS_STATEMENTS, TLX_FORM};
use crate::study::store::{claim, OpenStudy};
use crate::study::trials::{self, Mark};
use crate::study::view;
use axum::extract::{Query, State};
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::Json;
use maud::{html, Markup, DOCTYPE};
use serde::Deserialize;
use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::{Arc, Mutex};

/// The `netfi study next` children this server started, by data folder and
/// participant.
static TRIALS: Mutex<BTreeMap<(PathBuf, String), Child>> = Mutex::new(BTreeMap::new());

fn unprocessable(msg: impl std::fmt::Display) -> Response {
    (StatusCode::UNPROCESSABLE_ENTITY, format!("{msg}")).into_response()
}

/// Which study and participant a request is about.
#[derive(Debug, Deserialize)]
pub struct Which {
    file: Option<String>,
    participant: Option<String>,
}

fn open(file: Option<&str>) -> Result<OpenStudy, String> {
    let file = file.filter(|f| !f.is_empty()).ok_or("no study file: open one (its path on this host)")?;
    OpenStudy::open(Path::new(file)).map_err(|e| e.to_string())
}

/// `GET /study?file=…`: the experimenter's page.
pub async fn page(Query(w): Query<Which>) -> Markup {
    let file = w.file.clone().unwrap_or_default();
    let opened = if file.is_empty() { None } else { Some(tokio::task::spawn_blocking(move || open(Some(&file))).await.unwrap_or_else(|e| Err(e.to_string()))) };
    let body = html! {
        section id="study-file" {
            label { "study file " input id="study-path" size="60" value=(w.file.as_deref().unwrap_or("")); }
            button id="study-open" { "open" }
        }
        @match &opened {
            None => { p { "Give the path of a study file on this host." } }
            Some(Err(e)) => { pre id="study-error" class="error" { (e) } }
            Some(Ok(s)) => { (study_body(s, w.participant.as_deref())) }
        }
    };
    super::page::shell_with("study", "study", "/assets/study.js", body)
}

fn study_body(s: &OpenStudy, chosen: Option<&str>) -> Markup {
    let st = &s.study;
    let weighted = st.questionnaires.tlx_weighting == TlxWeighting::Pairwise;
    let changed = s.changed_inputs().unwrap_or_else(|e| vec![e.to_string()]);
    html! {
        h2 id="study-name" { (st.name) }
        ul id="study-changed" class="error" hidden[changed.is_empty()] { @for c in &changed { li { (c) } } }
        p { (st.participants.len()) " participants · " (st.conditions.len()) " conditions · seed " (st.seed) " · data in " code { (s.data.display()) } }
        section id="participant-box" {
            label { "participant "
                select id="participant" {
                    option value="" { "—" }
                    @for p in &st.participants {
                        option value=(p.id) selected[chosen == Some(p.id.as_str())] { (p.id) }
                    }
                }
            }
            " " a id="participant-view" href="#" target="_blank" { "participant's view" }
        }
        section id="next-box" hidden {
            h3 { "Next" }
            p id="next-text" {}
            div id="trial-controls" {
                button id="start-btn" { "start trial" }
                button id="stop-btn" { "stop trial" }
            }
            div id="mark-controls" {
                label { "note " input id="mark-note" size="40"; }
                @for m in &st.measures {
                    " " label { (m.label) " " input class="measure" data-name=(m.name) type="number" min="0" step="1" size="4"; }
                }
                button id="mark-done" { "done" }
                button id="mark-failed" { "failed" }
                button id="mark-repeat" { "repeat" }
            }
            pre id="study-action-error" class="error" {}
        }
        section id="sus-box" class="form" hidden {
            h3 id="sus-title" { "System Usability Scale" }
            p class="hint" { "Every statement answered, 1 (" (SUS_SCALE[0]) ") to 5 (" (SUS_SCALE[4]) "); none is chosen beforehand." }
            table id="sus-form" {
                tr { th { "" } @for (v, words) in SUS_SCALE.iter().enumerate() { th { (v + 1) br; small { (words) } } } }
                @for (i, statement) in SUS_STATEMENTS.iter().enumerate() {
                    tr class="sus-item" data-item=(i + 1) {
                        td { (i + 1) ". " (statement) }
                        @for v in 1..=5 { td { input type="radio" name={ "sus-" (i + 1) } value=(v) aria-label={ (i + 1) ": " (SUS_SCALE[v - 1]) }; } }
                    }
                }
            }
            p class="unanswered" id="sus-unanswered" {}
            button id="sus-submit" disabled { "record SUS" }
        }
        section id="tlx-box" class="form" hidden {
            h3 id="tlx-title" { "NASA-TLX" }
            p class="hint" { "Every scale marked, 0 to 100 in steps of 5; none is marked beforehand." }
            @for (k, scale) in TLX_FORM.iter().enumerate() {
                fieldset class="tlx-scale" data-scale=(scale.key) {
                    legend { b { (scale.title) } " — " (scale.question) }
                    span class="anchor" { (scale.low) }
                    @for v in (0..=100).step_by(5) { input type="radio" name={ "tlx-" (k) } value=(v) title=(v) aria-label={ (scale.title) " " (v) }; }
                    span class="anchor" { (scale.high) }
                }
            }
            @if weighted {
                fieldset id="tlx-pairs" {
                    legend { "Which of the two contributed more to the workload of the task?" }
                    @for (k, (a, b)) in tlx_pairs().into_iter().enumerate() {
                        div class="tlx-pair" data-pair=(k + 1) {
                            label { input type="radio" name={ "pair-" (k) } value=(a); " " (TLX_FORM[a].title) }
                            " or "
                            label { input type="radio" name={ "pair-" (k) } value=(b); " " (TLX_FORM[b].title) }
                        }
                    }
                }
            }
            p class="unanswered" id="tlx-unanswered" {}
            button id="tlx-submit" disabled { "record NASA-TLX" }
        }
        section id="missing-box" hidden {
            label { "not given, because " input id="missing-reason" size="40"; }
            button id="missing-submit" { "record as missing" }
        }
        section id="trials-box" hidden {
            h3 { "Schedule" }
            table id="trials" class="figures" {}
        }
    }
}

/// `GET /study/view?file=…&participant=…`: what the participant sees.
pub async fn participant_view(Query(w): Query<Which>) -> Response {
    let got = tokio::task::spawn_blocking(move || -> Result<(bool, view::ParticipantView), String> {
        let s = open(w.file.as_deref())?;
        let p = s.participant(w.participant.as_deref().unwrap_or_default()).map_err(|e| e.to_string())?;
        Ok((s.study.hide_condition, view::participant(&s, p).map_err(|e| e.to_string())?))
    })
    .await;
    let (hide, v) = match got {
        Ok(Ok(x)) => x,
        Ok(Err(e)) => return unprocessable(e),
        Err(e) => return (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    };
    let done = v.trials.iter().filter(|t| t.state == "done" || t.state == "failed").count();
    let what = match v.next.kind {
        "running" => "Trial in progress".to_string(),
        "trial" | "unmarked" => "Please wait for the experimenter".to_string(),
        "questionnaire" => "A questionnaire, please".to_string(),
        _ => "All trials are done. Thank you!".to_string(),
    };
    let condition = (!hide).then(|| v.next.condition.clone()).flatten();
    let body = html! {
        div id="participant-screen" {
            h2 { (v.participant) }
            p id="participant-progress" { "Trial " (done.min(v.trials.len())) " of " (v.trials.len()) " done" }
            p id="participant-state" { (what) }
            @if let Some(c) = condition { p id="participant-condition" { "Condition: " (c) } }
        }
    };
    let page = html! {
        (DOCTYPE)
        html lang="en" {
            head { meta charset="utf-8"; meta http-equiv="refresh" content="2"; title { "netfi" } link rel="stylesheet" href="/assets/app.css"; }
            body { main { (body) } }
        }
    };
    page.into_response()
}

/// `GET /api/study/status?file=…&participant=…`: the participant's
/// progress (JSON), and whether this server runs their trial.
pub async fn status(State(ui): State<Arc<super::Ui>>, Query(w): Query<Which>) -> Response {
    let got = tokio::task::spawn_blocking(move || -> Result<serde_json::Value, String> {
        let s = open(w.file.as_deref())?;
        let id = w.participant.unwrap_or_default();
        let p = s.participant(&id).map_err(|e| e.to_string())?;
        let v = view::participant(&s, p).map_err(|e| e.to_string())?;
        let dir = s.participant_dir(p);
        ui.runs.add_study_runs(v.trials.iter().filter_map(|t| Some((t.run_id.clone()?, dir.join(t.dir.as_ref()?)))));
        let mine = reap(&s.data, &id);
        let mut j = serde_json::to_value(&v).map_err(|e| e.to_string())?;
        j["started_here"] = serde_json::Value::Bool(mine);
        j["hide_condition"] = serde_json::Value::Bool(s.study.hide_condition);
        Ok(j)
    })
    .await;
    match got {
        Ok(Ok(j)) => Json(j).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// Whether this server's child for the participant is still going (a
/// child that ended is reaped).
fn reap(data: &Path, id: &str) -> bool {
    let mut trials = TRIALS.lock().expect("trials lock");
    let key = (data.to_path_buf(), id.to_string());
    match trials.get_mut(&key).map(|c| c.try_wait()) {
        Some(Ok(None)) => true,
        Some(_) => {
            trials.remove(&key);
            false
        }
        None => false,
    }
}

/// A state change's body.
#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Action {
    file: String,
    participant: String,
    /// `mark`: done, failed or repeat.
    #[serde(default)]
    how: Option<String>,
    #[serde(default)]
    note: Option<String>,
    /// `answer`: sus or tlx.
    #[serde(default)]
    instrument: Option<String>,
    /// The answers; an item the participant left untouched is null.
    #[serde(default)]
    values: Vec<Option<u32>>,
    /// A weighted TLX's 15 pairwise choices (the scale chosen in each).
    #[serde(default)]
    pairs: Option<Vec<Option<usize>>>,
    #[serde(default)]
    missing: Option<String>,
    /// `mark`: the study's measures counted in the trial.
    #[serde(default)]
    counts: BTreeMap<String, u32>,
}

/// `POST /api/study/start`: starts the participant's next trial (a
/// `netfi study next` child).
pub async fn start(State(ui): State<Arc<super::Ui>>, Json(a): Json<Action>) -> Response {
    let (file, who) = (a.file.clone(), a.participant.clone());
    // Refused here with the command line's own words (a questionnaire due,
    // a trial unmarked, someone else on it) rather than in a child's log.
    let checked = tokio::task::spawn_blocking(move || -> Result<(OpenStudy, PathBuf), (StatusCode, String)> {
        let bad = |e: String| (StatusCode::UNPROCESSABLE_ENTITY, e);
        let s = open(Some(&file)).map_err(bad)?;
        let p = s.participant(&who).map_err(|e| bad(e.to_string()))?;
        let v = view::participant(&s, p).map_err(|e| bad(e.to_string()))?;
        if let Some(holder) = v.busy {
            return Err((StatusCode::CONFLICT, format!("`{who}` is busy: {holder}")));
        }
        if v.next.kind != "trial" {
            return Err((StatusCode::CONFLICT, format!("no trial of `{who}` to start: {}", v.next.kind)));
        }
        let dir = s.participant_dir(p);
        std::fs::create_dir_all(&dir).map_err(|e| bad(format!("{}: {e}", dir.display())))?;
        Ok((s, dir))
    })
    .await;
    let (s, dir) = match checked {
        Ok(Ok(x)) => x,
        Ok(Err((code, why))) => return (code, why).into_response(),
        Err(e) => return (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    };
    if reap(&s.data, &a.participant) {
        return (StatusCode::CONFLICT, "this page is already running a trial of this participant").into_response();
    }
    let log = match crate::durable::create_fresh(&dir.join("ui-next.log")) {
        Ok(f) => f,
        Err(e) => return unprocessable(format!("{}: {e}", dir.join("ui-next.log").display())),
    };
    // Spawned on the server's own thread, not the blocking pool's: the
    // child's parent-death signal follows the thread that forked it.
    let mut cmd = Command::new(&ui.opts.netfi);
    cmd.args(["study", "next"]).arg(&s.file).args(["--participant", &a.participant]);
    cmd.stdin(Stdio::null()).stdout(log.try_clone().map(Stdio::from).unwrap_or(Stdio::null())).stderr(log);
    give_all_cores(&mut cmd);
    match cmd.spawn() {
        Ok(child) => {
            TRIALS.lock().expect("trials lock").insert((s.data.clone(), a.participant.clone()), child);
            StatusCode::NO_CONTENT.into_response()
        }
        Err(e) => unprocessable(format!("starting {}: {e}", ui.opts.netfi.display())),
    }
}

/// The child runs on every core this host has, as a `netfi run` from a
/// terminal would (the server itself keeps off the emulator's core, and a
/// child would inherit that), and stops its trial if the server ends.
fn give_all_cores(cmd: &mut Command) {
    use std::os::unix::process::CommandExt;
    // SAFETY: sysconf before the fork; the set is built here and copied.
    let n = unsafe { libc::sysconf(libc::_SC_NPROCESSORS_CONF) }.max(1) as usize;
    // SAFETY: a zeroed cpu_set_t is valid; CPU_SET on indices below its size.
    let mut set: libc::cpu_set_t = unsafe { std::mem::zeroed() };
    for c in 0..n.min(libc::CPU_SETSIZE as usize) {
        unsafe { libc::CPU_SET(c, &mut set) };
    }
    // SAFETY: sched_setaffinity and prctl are async-signal-safe; `set` is a copy owned by the closure.
    unsafe {
        cmd.pre_exec(move || {
            // Cores this process may not use (a cpuset) are left out by the kernel.
            let _ = libc::sched_setaffinity(0, std::mem::size_of::<libc::cpu_set_t>(), &set);
            if libc::prctl(libc::PR_SET_PDEATHSIG, libc::SIGTERM) != 0 {
                return Err(std::io::Error::last_os_error());
            }
            Ok(())
        });
    }
}

/// `POST /api/study/stop`: stops the trial this server started, as Ctrl-C
/// would (the run writes its report; the trial is marked stopped).
pub async fn stop(Json(a): Json<Action>) -> Response {
    let s = match open(Some(&a.file)) {
        Ok(s) => s,
        Err(e) => return unprocessable(e),
    };
    let trials = TRIALS.lock().expect("trials lock");
    match trials.get(&(s.data.clone(), a.participant.clone())) {
        Some(child) => {
            // SAFETY: signalling our own child, not yet reaped (reaping removes it from the map).
            unsafe { libc::kill(child.id() as libc::pid_t, libc::SIGINT) };
            StatusCode::NO_CONTENT.into_response()
        }
        None => match stop_elsewhere(&s, &a.participant) {
            Ok(()) => StatusCode::NO_CONTENT.into_response(),
            Err(why) => (StatusCode::CONFLICT, why).into_response(),
        },
    }
}

/// Stops a trial started elsewhere (a terminal's `netfi study next`, or
/// another server) as Ctrl-C would: SIGINT to the runner its attempt
/// names, once `/proc` shows that process is `netfi study next` of this
/// participant (a pid the kernel gave again is left alone).
fn stop_elsewhere(s: &OpenStudy, id: &str) -> Result<(), String> {
    let p = s.participant(id).map_err(|e| e.to_string())?;
    let state = crate::study::store::load_state(&s.participant_dir(p)).map_err(|e| e.to_string())?.unwrap_or_default();
    let running = state.attempts.iter().find(|a| a.state == crate::study::AttemptState::Running).ok_or_else(|| format!("no trial of `{id}` is running"))?;
    let pid = running.runner_pid.ok_or_else(|| format!("trial {} of `{id}` names no runner", running.trial))?;
    let cmdline = std::fs::read(format!("/proc/{pid}/cmdline")).unwrap_or_default();
    let words: Vec<&[u8]> = cmdline.split(|b| *b == 0).collect();
    let is_runner = words.windows(2).any(|w| w[0] == b"study" && w[1] == b"next") && words.contains(&id.as_bytes());
    if !is_runner {
        return Err(format!("trial {} of `{id}`: its runner (pid {pid}) is gone", running.trial));
    }
    let pid = libc::pid_t::try_from(pid).map_err(|_| format!("pid {pid}"))?;
    // SAFETY: kill with a pid just checked to be this participant's runner.
    if unsafe { libc::kill(pid, libc::SIGINT) } != 0 {
        return Err(format!("stopping pid {pid}: {}", std::io::Error::last_os_error()));
    }
    Ok(())
}

/// `POST /api/study/mark` `{file, participant, how, note}`.
pub async fn mark(Json(a): Json<Action>) -> Response {
    let done = tokio::task::spawn_blocking(move || -> Result<serde_json::Value, String> {
        let s = open(Some(&a.file))?;
        let p = s.participant(&a.participant).map_err(|e| e.to_string())?;
        let how = match a.how.as_deref() {
            Some("done") => Mark::Done,
            Some("failed") => Mark::Failed,
            Some("repeat") => Mark::Repeat,
            other => return Err(format!("how: done, failed or repeat, not {other:?}")),
        };
        let marked = trials::mark_counting(&s, p, None, how, a.note.as_deref().unwrap_or_default(), &a.counts).map_err(|e| e.to_string())?;
        serde_json::to_value(marked).map_err(|e| e.to_string())
    })
    .await;
    match done {
        Ok(Ok(j)) => Json(j).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// `POST /api/study/answer` `{file, participant, instrument, values | missing}`.
pub async fn answer(Json(a): Json<Action>) -> Response {
    let done = tokio::task::spawn_blocking(move || -> Result<String, String> {
        let s = open(Some(&a.file))?;
        let p = s.participant(&a.participant).map_err(|e| e.to_string())?;
        let instrument = match a.instrument.as_deref() {
            Some("sus") => Instrument::Sus,
            Some("tlx") => Instrument::Tlx,
            other => return Err(format!("instrument: sus or tlx, not {other:?}")),
        };
        // A form with an item left untouched is refused here too, not
        // only by the page: nothing is recorded that was not answered.
        let values = match a.missing {
            Some(_) if a.values.is_empty() => Vec::new(),
            Some(_) => return Err("either answers or a reason it is missing, not both".into()),
            None => questionnaire::complete(instrument, &a.values)?,
        };
        let pairs: Option<Vec<usize>> = match &a.pairs {
            None => None,
            Some(chosen) => {
                let open: Vec<String> = chosen.iter().enumerate().filter(|(_, c)| c.is_none()).map(|(k, _)| (k + 1).to_string()).collect();
                if !open.is_empty() {
                    return Err(format!("not answered: NASA-TLX pair {} (every pair is answered; none has a default)", open.join(", ")));
                }
                Some(chosen.iter().flatten().copied().collect())
            }
        };
        let (lock, state) = claim(&s, p, "netfi ui: a questionnaire").map_err(|e| e.to_string())?;
        let due = questionnaire::due_now(&s, p, instrument, |t| state.finished(t)).ok_or("that questionnaire is not due now")?;
        let path = questionnaire::record(&s, p, &due, &values, pairs.as_deref(), a.missing.as_deref()).map_err(|e| e.to_string())?;
        lock.release();
        Ok(path.display().to_string())
    })
    .await;
    match done {
        Ok(Ok(path)) => Json(serde_json::json!({ "file": path })).into_response(),
        Ok(Err(e)) => unprocessable(e),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

/// `GET /assets/study.js`.
pub async fn script() -> impl IntoResponse {
    ([(header::CONTENT_TYPE, "text/javascript; charset=utf-8")], STUDY_JS)
}

/// The page's script: plain, talks only to this server, every state change
/// a JSON POST with the page's header (the guard refuses anything else).
const STUDY_JS: &str = concat!(include_str!("assets/call.js"), include_str!("assets/study.js"));
