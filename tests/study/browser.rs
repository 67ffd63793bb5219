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
    for i in 1..=10 {
        choose(&tab, &format!("sus-{i}"), if i % 2 == 1 { 4 } else { 2 });
    }
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

/// Whether every radio button of `box_id` is unchosen.
fn none_chosen(tab: &Tab, box_id: &str) -> bool {
    js(tab, &format!("document.querySelectorAll('#{box_id} input[type=radio]:checked').length === 0")) == serde_json::Value::Bool(true)
}

/// Chooses `value` in the radio group `name`, as a click does.
fn choose(tab: &Tab, name: &str, value: u32) {
    let done = js(tab, &format!("(() => {{ const r = document.querySelector('input[name=\"{name}\"][value=\"{value}\"]'); if (!r) return false; r.click(); return r.checked; }})()"));
    assert_eq!(done, serde_json::Value::Bool(true), "{name} = {value}");
}

/// What the server answers the page's own call of `body` to
/// `/api/study/answer`: `accepted`, or its refusal.
fn answer_directly(tab: &Tab, body: &str) -> String {
    let code = format!("(async () => {{ try {{ await call('POST', '/api/study/answer', {body}); return 'accepted'; }} catch (e) {{ return e.message; }} }})()");
    js(tab, &code).as_str().unwrap_or_default().to_string()
}

fn disabled(tab: &Tab, id: &str) -> bool {
    js(tab, &format!("document.getElementById('{id}').disabled")) == serde_json::Value::Bool(true)
}

#[test]
fn a_questionnaire_is_refused_until_every_item_is_answered_then_recorded() {
    let Some(browser) = browser_or_skip() else { return };
    let _one = machine::alone();
    let dir = Scratch::new("forms");
    let file = dir.file(
        "study.toml",
        "name = \"forms\"\nseed = 9\ndata = \"data\"\n[trial]\nduration_s = \"1min\"\nrun_args = [\"--no-isolate\"]\n\
         [questionnaires]\nsus = \"start\"\ntlx = \"trial\"\ntlx_weighting = \"pairwise\"\n\
         [[measure]]\nname = \"drops\"\nlabel = \"Pegs dropped\"\n\
         [[block]]\nname = \"only\"\nconditions = [\"PLM-2\"]\n[[participant]]\nid = \"P9\"\n",
    );
    let ui = Ui::start(&dir.0.join("runs"));
    let tab = browser.new_tab().unwrap();
    let path = file.display().to_string();
    tab.navigate_to(&format!("{}/study?file={path}", ui.base)).unwrap().wait_until_navigated().unwrap();
    until(&tab, "document.getElementById('study-name')?.textContent === 'forms'", 20);
    js(&tab, "(() => { const s = document.getElementById('participant'); s.value = 'P9'; s.dispatchEvent(new Event('change')); return true; })()");
    until(&tab, "!document.getElementById('sus-box').hidden", 20);

    // The SUS: its ten statements and words, nothing chosen beforehand.
    let form = js(&tab, "document.getElementById('sus-box').innerText").as_str().unwrap_or_default().to_string();
    for words in ["I found the system unnecessarily complex.", "I felt very confident using the system.", "Strongly disagree", "Strongly agree"] {
        assert!(form.contains(words), "the SUS form lacks `{words}`:\n{form}");
    }
    assert_eq!(js(&tab, "document.querySelectorAll('#sus-box tr.sus-item').length"), serde_json::json!(10));
    assert!(none_chosen(&tab, "sus-box") && disabled(&tab, "sus-submit"));
    for i in 1..=9 {
        choose(&tab, &format!("sus-{i}"), if i % 2 == 1 { 4 } else { 2 });
    }
    assert!(disabled(&tab, "sus-submit"), "nine of ten answered");
    assert!(js(&tab, "document.getElementById('sus-unanswered').textContent").as_str().unwrap().contains("statement 10"));
    // What the page does not send, the server refuses too.
    let said = answer_directly(&tab, &format!("{{ file: {path:?}, participant: 'P9', instrument: 'sus', values: [4, 2, 4, 2, 4, 2, 4, 2, 4, null] }}"));
    assert!(said.contains("not answered: SUS item 10"), "{said}");
    let sus_file = dir.0.join("data/P9/questionnaires/sus.json");
    assert!(!sus_file.exists(), "nothing recorded");
    choose(&tab, "sus-10", 2);
    assert!(!disabled(&tab, "sus-submit"));
    click(&tab, "#sus-submit");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'trial'", 20);
    let sus: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(&sus_file).unwrap()).unwrap();
    assert_eq!(sus["score"], 75.0, "items 4,2,4,2,… score 2.5 × (5·3 + 5·3)");

    // A trial, stopped from the page, marked with a note and a count.
    click(&tab, "#start-btn");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'running' && !document.getElementById('stop-btn').disabled", 60);
    let ready = dir.0.join("data/P9/trial-01-PLM-2/console.ready");
    super::wait_for("the trial to stream", 60, || ready.exists());
    click(&tab, "#stop-btn");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'unmarked'", 60);
    js(&tab, "(() => { document.getElementById('mark-note').value = 'two pegs dropped'; document.querySelector('.measure[data-name=drops]').value = '2'; return true; })()");
    click(&tab, "#mark-done");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'questionnaire'", 20);
    assert_eq!(js(&tab, "document.getElementById('mark-note').value + '|' + document.querySelector('.measure').value"), serde_json::json!("|"), "the note and count are the trial's, cleared once it is marked");
    let state: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P9/state.json")).unwrap()).unwrap();
    let a = &state["attempts"][0];
    assert_eq!((a["state"].as_str(), a["stopped"].as_bool(), a["note"].as_str(), a["counts"]["drops"].as_u64()), (Some("done"), Some(true), Some("two pegs dropped"), Some(2)), "{a}");
    until(&tab, "document.querySelector('#trials tr[data-state=\"done\"]')?.textContent.includes('(stopped)') === true", 10);

    // The NASA-TLX after that trial: its title, its anchors, its pairs.
    until(&tab, "!document.getElementById('tlx-box').hidden", 20);
    let title = js(&tab, "document.getElementById('tlx-title').textContent");
    assert_eq!(title, serde_json::json!("NASA-TLX after trial 1 (PLM-2, block only)"));
    let form = js(&tab, "document.getElementById('tlx-box').innerText").as_str().unwrap_or_default().to_string();
    for words in ["Mental Demand", "How hurried or rushed was the pace of the task?", "Perfect", "Failure", "Very Low", "Very High"] {
        assert!(form.contains(words), "the TLX form lacks `{words}`:\n{form}");
    }
    assert_eq!(js(&tab, "document.querySelectorAll('#tlx-box .tlx-pair').length"), serde_json::json!(15));
    assert!(none_chosen(&tab, "tlx-box") && disabled(&tab, "tlx-submit"));
    let ratings = [55, 30, 40, 25, 60, 35];
    for (k, v) in ratings.iter().enumerate() {
        choose(&tab, &format!("tlx-{k}"), *v);
    }
    assert!(disabled(&tab, "tlx-submit"), "the pairs are not chosen yet");
    // The first scale of each pair but the last.
    let pairs: Vec<(u32, u32)> = (0..6).flat_map(|a| (a + 1..6).map(move |b| (a, b))).collect();
    for (k, (a, _)) in pairs.iter().enumerate().take(14) {
        choose(&tab, &format!("pair-{k}"), *a);
    }
    assert!(disabled(&tab, "tlx-submit"));
    assert!(js(&tab, "document.getElementById('tlx-unanswered').textContent").as_str().unwrap().contains("pair 15"));
    let body = format!("{{ file: {path:?}, participant: 'P9', instrument: 'tlx', values: {ratings:?}, pairs: [0,0,0,0,0,1,1,1,1,2,2,2,3,3,null] }}");
    let said = answer_directly(&tab, &body);
    assert!(said.contains("not answered: NASA-TLX pair 15"), "{said}");
    choose(&tab, "pair-14", 4);
    click(&tab, "#tlx-submit");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'finished'", 20);
    let tlx: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P9/questionnaires/tlx-01.json")).unwrap()).unwrap();
    assert_eq!(tlx["values"], serde_json::json!(ratings));
    assert_eq!(tlx["weights"], serde_json::json!([5, 4, 3, 2, 1, 0]));
    assert_eq!(tlx["weighted"].as_f64(), Some(625.0 / 15.0));

    // The trial is a run of the server: in /runs, with its report.
    let run_id = super::status(&file, "P9")["trials"][0]["run_id"].as_str().unwrap().to_string();
    let runs = browser.new_tab().unwrap();
    runs.navigate_to(&format!("{}/runs", ui.base)).unwrap().wait_until_navigated().unwrap();
    let listed = js(&runs, &format!("document.querySelector('tr.run[data-id=\"{run_id}\"] a[href=\"/runs/{run_id}/report\"]') !== null"));
    assert_eq!(listed, serde_json::Value::Bool(true), "{run_id} in /runs:\n{}", js(&runs, "document.body.innerText"));
    runs.navigate_to(&format!("{}/runs/{run_id}/report", ui.base)).unwrap().wait_until_navigated().unwrap();
    let report = js(&runs, "document.body.innerText").as_str().unwrap_or_default().to_string();
    assert!(report.contains("PLM-2"), "the trial's run report:\n{report}");
    assert_eq!(js(&tab, &format!("document.querySelector('#trials a[href=\"/runs/{run_id}/report\"]') !== null")), serde_json::Value::Bool(true));
}

/// The page drives a trial with the lab's console and robot (the test's
/// UDP sockets): it says whom the trial waits for, the console streams,
/// the experimenter stops the trial and marks it, and its motion is what
/// the console sent.
#[test]
fn the_study_page_drives_a_trial_with_the_labs_console() {
    let Some(browser) = browser_or_skip() else { return };
    let _one = machine::alone();
    let dir = Scratch::new("page-lab");
    let robot = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let console = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
    let ingress = std::net::UdpSocket::bind("127.0.0.1:0").unwrap().local_addr().unwrap();
    let file = dir.file(
        "study.toml",
        &format!(
            "name = \"page-lab\"\nseed = 3\ndata = \"data\"\n[trial]\nduration_s = 60\npeers = \"lab\"\n\
             [trial.lab]\ningress = \"udp://{ingress}\"\nconsole-from = \"{}\"\negress = \"udp://{}\"\n\
             [questionnaires]\nsus = \"none\"\ntlx = \"none\"\n[[block]]\nname = \"only\"\nconditions = [\"Normal\"]\n[[participant]]\nid = \"P8\"\n",
            console.local_addr().unwrap(),
            robot.local_addr().unwrap()
        ),
    );
    let ui = Ui::start(&dir.0.join("runs"));
    let tab = browser.new_tab().unwrap();
    tab.navigate_to(&format!("{}/study?file={}", ui.base, file.display())).unwrap().wait_until_navigated().unwrap();
    until(&tab, "document.getElementById('study-name')?.textContent === 'page-lab'", 20);
    js(&tab, "(() => { const s = document.getElementById('participant'); s.value = 'P8'; s.dispatchEvent(new Event('change')); return true; })()");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'trial'", 20);
    click(&tab, "#start-btn");
    until(&tab, "document.getElementById('next-text').textContent.includes(\"waiting for the lab's console\")", 60);
    let mut sent = 0.0;
    for s in 0..300u32 {
        let mut b = [0u8; 124];
        let mut v = netfi::frame::ItpView::new_unchecked(&mut b[..]);
        v.set_sequence(s);
        v.set_delx([3, 0]);
        v.set_dely([4, 0]);
        v.set_surgeon_mode(1);
        v.fill_checksum();
        console.send_to(&b, ingress).unwrap();
        sent += 0.05;
        std::thread::sleep(Duration::from_millis(1));
    }
    until(&tab, "document.getElementById('next-text').dataset.kind === 'running' && !document.getElementById('next-text').textContent.includes('waiting')", 30);
    click(&tab, "#stop-btn");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'unmarked'", 60);
    click(&tab, "#mark-done");
    until(&tab, "document.getElementById('next-text').dataset.kind === 'finished'", 20);
    let state: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P8/state.json")).unwrap()).unwrap();
    let a = &state["attempts"][0];
    assert_eq!((a["state"].as_str(), a["stopped"].as_bool()), (Some("done"), Some(true)), "{a}");
    let figures: serde_json::Value = serde_json::from_str(&std::fs::read_to_string(dir.0.join("data/P8").join(a["dir"].as_str().unwrap()).join("figures.json")).unwrap()).unwrap();
    // Each frame moves arm 0 by a 3-4-5 step: 5 units, 0.05 mm.
    let got = figures["figures"]["console_motion_arm0_mm"].as_f64().unwrap();
    assert!((got - sent).abs() < 1e-9, "console motion {got} mm, the test's console sent {sent} mm");
}
