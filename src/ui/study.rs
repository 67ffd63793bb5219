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

use crate::study::questionnaire::{self, Instrument, TLX_SCALES};
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
    html! {
        h2 id="study-name" { (st.name) }
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
                button id="mark-done" { "done" }
                button id="mark-failed" { "failed" }
                button id="mark-repeat" { "repeat" }
            }
            pre id="study-action-error" class="error" {}
        }
        section id="sus-box" hidden {
            h3 { "System Usability Scale" }
            p { "1 = strongly disagree … 5 = strongly agree" }
            @for i in 1..=questionnaire::SUS_ITEMS {
                label class="q" { (format!("item {i} ")) select class="sus-item" { @for v in 1..=5 { option value=(v) selected[v == 3] { (v) } } } }
            }
            button id="sus-submit" { "record SUS" }
        }
        section id="tlx-box" hidden {
            h3 { "NASA-TLX " span id="tlx-block" {} }
            @for s in TLX_SCALES {
                label class="q" { (s.replace('_', " ")) " " input class="tlx-scale" type="range" min="0" max="100" step="5" value="50"; output {} }
            }
            button id="tlx-submit" { "record NASA-TLX" }
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
pub async fn status(Query(w): Query<Which>) -> Response {
    let got = tokio::task::spawn_blocking(move || -> Result<serde_json::Value, String> {
        let s = open(w.file.as_deref())?;
        let id = w.participant.unwrap_or_default();
        let p = s.participant(&id).map_err(|e| e.to_string())?;
        let v = view::participant(&s, p).map_err(|e| e.to_string())?;
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
    #[serde(default)]
    values: Vec<u32>,
    #[serde(default)]
    missing: Option<String>,
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
        None => (StatusCode::CONFLICT, format!("no trial of `{}` was started from this page", a.participant)).into_response(),
    }
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
        let marked = trials::mark(&s, p, None, how, a.note.as_deref().unwrap_or_default()).map_err(|e| e.to_string())?;
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
        let (lock, state) = claim(&s, p, "netfi ui: a questionnaire").map_err(|e| e.to_string())?;
        let due = questionnaire::due_now(&s, p, instrument, |t| state.finished(t)).ok_or("that questionnaire is not due now")?;
        let path = questionnaire::record(&s, p, &due, &a.values, a.missing.as_deref()).map_err(|e| e.to_string())?;
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
