//! `netfi ui` driven in a real browser (headless chromium over the DevTools
//! protocol), as a user would: build a PLM-2 scenario, preview it, run it
//! for a few seconds, switch it to DLM-1 live, and open the report. Asserts
//! on what the pages show. Skips with a message where no chromium is
//! installed, unless `NETFI_REQUIRE_BROWSER` is set (`.ci/run` sets it).
//!
//! With `NETFI_UI_SCREENSHOTS=DIR`, each page is also saved there as PNG
//! (how docs/ui/ was made).

use headless_chrome::protocol::cdp::Page::CaptureScreenshotFormatOption;
use headless_chrome::{Browser, LaunchOptions, Tab};
use std::io::{BufRead, BufReader};
use std::path::{Path, PathBuf};
use std::process::{Child, Command, Stdio};
use std::sync::Arc;
use std::time::{Duration, Instant};

fn chromium() -> Option<PathBuf> {
    if let Some(p) = std::env::var_os("NETFI_CHROMIUM") {
        return Some(PathBuf::from(p));
    }
    let path = std::env::var_os("PATH")?;
    ["chromium", "chromium-browser", "google-chrome", "google-chrome-stable"]
        .iter()
        .flat_map(|name| std::env::split_paths(&path).map(move |d| d.join(name)))
        .find(|p| p.is_file())
}

fn browser_or_skip() -> Option<Browser> {
    let Some(path) = chromium() else {
        assert!(std::env::var_os("NETFI_REQUIRE_BROWSER").is_none(), "NETFI_REQUIRE_BROWSER is set but no chromium was found");
        eprintln!("SKIP: no chromium on PATH (set NETFI_CHROMIUM): the browser tests did not run");
        return None;
    };
    let opts = LaunchOptions::default_builder()
        .path(Some(path))
        .headless(true)
        // Root in a container has no user namespace for the sandbox.
        .sandbox(false)
        .window_size(Some((1280, 1600)))
        // Nothing of the browser's in /dev/shm: a test leaves the host as it found it.
        .args(vec![std::ffi::OsStr::new("--disable-dev-shm-usage")])
        .idle_browser_timeout(Duration::from_secs(300))
        .build()
        .expect("launch options");
    Some(Browser::new(opts).expect("starting chromium"))
}

/// A `netfi ui` on a free loopback port, stopped (SIGINT) when dropped.
struct Server {
    child: Child,
    url: String,
    out: PathBuf,
}

impl Server {
    fn start() -> Server {
        let out = std::env::temp_dir().join(format!("netfi-ui-test-{}", std::process::id()));
        let mut child = Command::new(env!("CARGO_BIN_EXE_netfi"))
            .args(["ui", "--port", "0", "--out"])
            .arg(&out)
            .stdout(Stdio::piped())
            .spawn()
            .expect("starting netfi ui");
        let mut line = String::new();
        BufReader::new(child.stdout.take().unwrap()).read_line(&mut line).unwrap();
        let url = line.trim().strip_prefix("netfi ui on ").unwrap_or_else(|| panic!("unexpected first line `{line}`")).to_string();
        Server { child, url, out }
    }
}

impl Drop for Server {
    fn drop(&mut self) {
        unsafe { libc::kill(self.child.id() as i32, libc::SIGINT) };
        let _ = self.child.wait();
        let _ = std::fs::remove_dir_all(&self.out);
    }
}

fn js(tab: &Tab, code: &str) -> serde_json::Value {
    tab.evaluate(code, true).unwrap_or_else(|e| panic!("{code}: {e}")).value.unwrap_or(serde_json::Value::Null)
}

/// Waits until `code` evaluates to something truthy; its value.
fn until(tab: &Tab, code: &str, secs: u64) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let v = js(tab, code);
        let truthy = !matches!(&v, serde_json::Value::Null | serde_json::Value::Bool(false))
            && v.as_str() != Some("")
            && v.as_f64() != Some(0.0);
        if truthy {
            return v;
        }
        if t0.elapsed() > Duration::from_secs(secs) {
            let page = js(tab, "document.querySelector('main')?.innerText ?? document.body.innerText");
            panic!("timed out waiting for `{code}`; the page shows:\n{}", page.as_str().unwrap_or_default());
        }
        std::thread::sleep(Duration::from_millis(100));
    }
}

fn text(tab: &Tab, id: &str) -> String {
    js(tab, &format!("document.getElementById('{id}')?.textContent ?? ''")).as_str().unwrap_or_default().to_string()
}

fn click(tab: &Tab, selector: &str) {
    tab.wait_for_element(selector).unwrap_or_else(|e| panic!("{selector}: {e}")).click().unwrap();
}

fn screenshot(tab: &Tab, name: &str) {
    let Some(dir) = std::env::var_os("NETFI_UI_SCREENSHOTS") else { return };
    let png = tab.capture_screenshot(CaptureScreenshotFormatOption::Png, None, None, true).expect("screenshot");
    std::fs::write(Path::new(&dir).join(name), png).expect("writing the screenshot");
}

/// The number of data points the SVG `svg_id` draws (polyline/path
/// vertices and rectangles).
fn svg_points(tab: &Tab, svg_id: &str) -> u64 {
    let code = format!(
        "(() => {{ const s = document.getElementById('{svg_id}'); if (!s) return 0; \
         let n = s.querySelectorAll('rect, circle').length; \
         for (const p of s.querySelectorAll('polyline, path')) \
           n += ((p.getAttribute('points') || p.getAttribute('d') || '').match(/[0-9.]+[ ,][0-9.]+/g) || []).length; \
         return n; }})()"
    );
    js(tab, &code).as_u64().unwrap_or(0)
}

fn builder(tab: &Arc<Tab>, server: &Server) {
    tab.navigate_to(&server.url).unwrap().wait_until_navigated().unwrap();
    until(tab, "document.querySelectorAll('#stages fieldset').length", 10);
    // Start from nothing: remove the example stage, add the study's PLM-2.
    click(tab, "#stages button.remove");
    js(tab, "document.getElementById('add-preset').value = 'PLM-2'");
    click(tab, "#add-preset-btn");
    let toml = js(tab, "document.getElementById('toml').value").as_str().unwrap().to_string();
    assert!(toml.contains("preset = \"PLM-2\""), "{toml}");
}

#[test]
fn build_preview_run_switch_report() {
    let Some(browser) = browser_or_skip() else { return };
    let server = Server::start();
    let tab = browser.new_tab().unwrap();
    builder(&tab, &server);

    // The preview: PLM-2 realizes 30% loss; its 95% interval over 100 000
    // frames is about ±0.01 wide around 0.3 (the burst lengths widen it):
    // 0.25–0.35 is several intervals.
    click(&tab, "#preview-btn");
    until(&tab, "!!document.getElementById('preview-loss')", 60);
    let loss: f64 = text(&tab, "preview-loss").parse().unwrap();
    assert!((0.25..0.35).contains(&loss), "preview realized loss {loss}");
    assert!(svg_points(&tab, "plot-loss-raster") > 1000, "the loss raster shows no drops");
    assert!(svg_points(&tab, "plot-loss-runs") > 3, "the burst-length histogram has no bars");
    screenshot(&tab, "builder.png");

    // A bad parameter: the parser's own message, naming the field.
    js(&tab, "document.getElementById('toml').value = 'name = \"x\"\\n[[stage]]\\nmodel = \"bernoulli\"\\np = 1.5\\n'");
    click(&tab, "#preview-btn");
    let err = until(&tab, "document.getElementById('preview-error')?.textContent", 30).as_str().unwrap().to_string();
    assert!(err.contains("`p`") && err.contains("probability"), "{err}");

    // Run it for a few seconds, switch to DLM-1 live.
    builder(&tab, &server);
    js(&tab, "document.getElementById('duration').value = '4s'");
    click(&tab, "#run-btn");
    until(&tab, "location.pathname.startsWith('/runs/') && document.getElementById('run-state')?.textContent === 'running'", 60);
    std::thread::sleep(Duration::from_millis(1500));
    js(&tab, "document.getElementById('switch-to').value = 'DLM-1'");
    click(&tab, "#switch-btn");
    let events = until(&tab, "document.getElementById('events').textContent", 20).as_str().unwrap().to_string();
    assert!(events.contains("DLM-1"), "events: {events}");
    screenshot(&tab, "run.png");
    until(&tab, "!document.getElementById('done').hidden", 120);
    assert_eq!(text(&tab, "run-state"), "done", "{}", text(&tab, "run-stderr"));
    let run_loss: f64 = text(&tab, "run-loss").parse().unwrap();
    assert!(run_loss > 0.0 && run_loss < 0.5, "run realized loss {run_loss}");

    // The report page: the same loss figure, the switch, plots with data.
    click(&tab, "#report-link");
    until(&tab, "!!document.getElementById('realized-loss')", 60);
    let shown = text(&tab, "realized-loss");
    assert!(shown.contains(&format!("{run_loss:.4}")), "report shows `{shown}`, the run {run_loss:.4}");
    assert!(text(&tab, "events").contains("DLM-1"), "the report's events lack the switch");
    let plotted = js(&tab, "JSON.stringify(Array.from(document.querySelectorAll('svg[id^=plot-]')).map(s => s.id))");
    let ids: Vec<String> = serde_json::from_str(plotted.as_str().unwrap_or("[]")).unwrap();
    assert!(ids.iter().any(|id| svg_points(&tab, id) > 20), "no plot with data points among {ids:?}");
    screenshot(&tab, "report.png");
}
