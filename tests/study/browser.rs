//! The experimenter's page in headless chromium: open a study, choose the
//! participant, record the SUS, start a trial, stop it, mark it; the
//! participant's view never names the condition when the study hides it.
//! Skips with a message where no chromium is installed, unless
//! `NETFI_REQUIRE_BROWSER` is set (`.ci/run` sets it).

use super::Scratch;
use crate::common::machine;
use headless_chrome::{Browser, Tab};
use std::process::Child;
use std::time::{Duration, Instant};

fn browser_or_skip() -> Option<Browser> {
    crate::common::browser::launch_or_skip("the study page's browser test", 1400, &[])
}

/// `netfi ui` on a free loopback port without a token, stopped when dropped.
struct Ui {
    child: Child,
    base: String,
}

impl Ui {
    fn start(out: &std::path::Path) -> Ui {
        let (child, url) = crate::common::netfi::ui(out, &["--no-token"]);
        Ui { child, base: url.trim_end_matches('/').to_string() }
    }
}

impl Drop for Ui {
    fn drop(&mut self) {
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let _ = self.child.wait();
    }
}

fn js(tab: &Tab, code: &str) -> serde_json::Value {
    tab.evaluate(code, true).unwrap_or_else(|e| panic!("{code}: {e}")).value.unwrap_or(serde_json::Value::Null)
}

fn until(tab: &Tab, code: &str, secs: u64) {
    let t0 = Instant::now();
    while js(tab, code) != serde_json::Value::Bool(true) {
        if t0.elapsed() > Duration::from_secs(secs) {
            let page = js(tab, "document.body.innerText");
            panic!("timed out waiting for `{code}`; the page shows:\n{}", page.as_str().unwrap_or_default());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

/// Clicks the button `selector` as the page's own script sees a click (the
/// DevTools mouse events wait for a paint that a headless tab on a loaded
/// machine may not make in time).
fn click(tab: &Tab, selector: &str) {
    tab.wait_for_element(selector).unwrap_or_else(|e| panic!("{selector}: {e}"));
    let clicked = js(tab, &format!("(() => {{ const b = document.querySelector('{selector}'); if (!b || b.disabled) return false; b.click(); return true; }})()"));
    assert_eq!(clicked, serde_json::Value::Bool(true), "{selector} is missing or disabled");
}

#[test]
fn the_study_page_drives_a_trial_in_a_browser() {
    let Some(browser) = browser_or_skip() else { return };
    let _one = machine::alone();
    let dir = Scratch::new("page");
    let file = dir.file(
        "study.toml",
        "name = \"page\"\nseed = 3\ndata = \"data\"\nhide_condition = true\n[trial]\nduration_s = 60\nrun_args = [\"--no-isolate\"]\n\
         [questionnaires]\nsus = \"start\"\n[[block]]\nname = \"only\"\nconditions = [\"PLM-2\"]\n[[participant]]\nid = \"P7\"\n",
    );
    let ui = Ui::start(&dir.0.join("runs"));
    let tab = browser.new_tab().unwrap();
    let q = format!("file={}", file.display());
    tab.navigate_to(&format!("{}/study?{q}", ui.base)).unwrap().wait_until_navigated().unwrap();
    until(&tab, "document.getElementById('study-name')?.textContent === 'page'", 20);
    js(&tab, "(() => { const s = document.getElementById('participant'); s.value = 'P7'; s.dispatchEvent(new Event('change')); return true; })()");
    until(&tab, "!document.getElementById('sus-box').hidden", 20);
    // The participant's view while a trial is next: progress, no condition.
    let view = browser.new_tab().unwrap();
    view.navigate_to(&format!("{}/study/view?{q}&participant=P7", ui.base)).unwrap().wait_until_navigated().unwrap();
    let shown = js(&view, "document.body.innerText").as_str().unwrap_or_default().to_string();
    assert!(shown.contains("Trial 0 of 1") && !shown.contains("PLM"), "the participant's view: {shown}");
    js(&tab, "(() => { document.querySelectorAll('.sus-item').forEach((s, i) => s.value = String(i % 2 ? 2 : 4)); return true; })()");
    click(&tab, "#sus-submit");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'trial'", 20);
    assert!(js(&tab, "document.getElementById('next-text').textContent").as_str().unwrap().contains("PLM-2"));
    click(&tab, "#start-btn");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'running' && !document.getElementById('stop-btn').disabled", 60);
    // Let it stream, then stop it as the experimenter does when the task is done.
    let ready = dir.0.join("data/P7/trial-01-PLM-2/console.ready");
    super::wait_for("the trial to stream", 60, || ready.exists());
    std::thread::sleep(Duration::from_millis(500));
    click(&tab, "#stop-btn");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'unmarked'", 60);
    js(&tab, "(() => { document.getElementById('mark-note').value = 'six pegs'; return true; })()");
    click(&tab, "#mark-done");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'finished'", 20);
    until(&tab, "document.querySelector('#trials tr[data-state=\"done\"]') !== null", 10);
    let state: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P7/state.json")).unwrap()).unwrap();
    let a = &state["attempts"][0];
    assert_eq!((a["state"].as_str(), a["stopped"].as_bool(), a["report"].as_bool()), (Some("done"), Some(true), Some(true)), "{a}");
    assert_eq!(a["note"], "six pegs");
    let sus: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P7/questionnaires/sus.json")).unwrap()).unwrap();
    assert_eq!(sus["score"], 75.0, "items 4,2,4,2,… score 2.5 × (5·3 + 5·3)");
    // A plain form post is refused: state changes come from the page only.
    let addr = ui.base.trim_start_matches("http://");
    let mut s = std::net::TcpStream::connect(addr).unwrap();
    use std::io::{Read, Write};
    let body = format!("{{\"file\":\"{}\",\"participant\":\"P7\"}}", file.display());
    write!(s, "POST /api/study/start HTTP/1.1\r\nHost: {addr}\r\nConnection: close\r\nContent-Type: application/x-www-form-urlencoded\r\nContent-Length: {}\r\n\r\n{body}", body.len()).unwrap();
    let mut resp = String::new();
    s.read_to_string(&mut resp).unwrap();
    assert!(resp.starts_with("HTTP/1.1 403"), "{resp}");
}
