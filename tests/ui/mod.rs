//! `netfi ui` driven in a real browser (headless chromium over the DevTools
//! protocol), as a user would: build a PLM-2 scenario, preview it, run it
//! for a few seconds, switch it to DLM-1 live, and open the report. Asserts
//! on what the pages show. And as a hostile page would: another origin's
//! page posting a form and fetching, a page reaching the server by a name
//! that resolves here (DNS rebinding); and on the wire, without the token.
//! The browser tests skip with a message where no chromium is installed,
//! unless `NETFI_REQUIRE_BROWSER` is set (`.ci/run` sets it).
//!
//! With `NETFI_UI_SCREENSHOTS=DIR`, each page is also saved there as PNG
//! (how docs/ui/ was made).

use headless_chrome::protocol::cdp::Page::CaptureScreenshotFormatOption;
use headless_chrome::{Browser, Tab};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};
use std::process::{Child, Command};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Arc;

use crate::common::machine;
use std::time::{Duration, Instant};

fn browser_or_skip() -> Option<Browser> {
    browser_with_or_skip(&[])
}

/// Chromium with `extra` command-line switches.
fn browser_with_or_skip(extra: &[&str]) -> Option<Browser> {
    crate::common::browser::launch_or_skip("the browser tests", 1600, extra)
}

/// A `netfi ui` on a free loopback port, stopped (SIGINT) when dropped.
struct Server {
    child: Child,
    /// The URL it printed, with its token.
    url: String,
    /// `127.0.0.1:PORT`.
    addr: String,
    token: String,
    out: PathBuf,
}

impl Server {
    fn start() -> Server {
        Server::start_with(&[])
    }

    fn start_with(args: &[&str]) -> Server {
        static N: AtomicUsize = AtomicUsize::new(0);
        let out = std::env::temp_dir().join(format!("netfi-ui-test-{}-{}", std::process::id(), N.fetch_add(1, Ordering::Relaxed)));
        let (child, url) = crate::common::netfi::ui(&out, args);
        let rest = url.strip_prefix("http://").unwrap_or_else(|| panic!("not an http URL: {url}"));
        let (addr, query) = rest.split_once("/?").unwrap_or_else(|| panic!("no token in the printed URL {url}"));
        let token = query.strip_prefix("token=").unwrap_or_else(|| panic!("no token in the printed URL {url}")).to_string();
        let addr = addr.replace("0.0.0.0", "127.0.0.1");
        Server { child, url, addr, token, out }
    }

    fn port(&self) -> u16 {
        self.addr.rsplit_once(':').unwrap().1.parse().unwrap()
    }

    /// The cookie the printed URL sets.
    fn cookie(&self) -> String {
        format!("netfi-ui-{}={}", self.port(), self.token)
    }

    /// A request on the wire: `method path`, `headers` (`Host` is this
    /// server's unless given), `body`; the status, headers and body.
    fn http(&self, method: &str, path: &str, headers: &[(&str, &str)], body: &str) -> (u16, String, String) {
        let mut s = std::net::TcpStream::connect(&self.addr).unwrap();
        s.set_read_timeout(Some(Duration::from_secs(60))).unwrap();
        let mut req = format!("{method} {path} HTTP/1.1\r\nConnection: close\r\nContent-Length: {}\r\n", body.len());
        if !headers.iter().any(|(k, _)| k.eq_ignore_ascii_case("host")) {
            req += &format!("Host: {}\r\n", self.addr);
        }
        for (k, v) in headers {
            req += &format!("{k}: {v}\r\n");
        }
        req += "\r\n";
        req += body;
        s.write_all(req.as_bytes()).unwrap();
        let mut resp = String::new();
        s.read_to_string(&mut resp).unwrap();
        let (head, body) = resp.split_once("\r\n\r\n").unwrap_or((&resp, ""));
        let status = head.split_whitespace().nth(1).and_then(|c| c.parse().ok()).unwrap_or_else(|| panic!("no status in {head}"));
        (status, head.to_string(), body.to_string())
    }

    /// A state change as the page makes it (JSON, its header, the cookie).
    fn post_as_the_page(&self, path: &str, body: &str) -> (u16, String) {
        let cookie = self.cookie();
        let origin = format!("http://{}", self.addr);
        let headers = [("Content-Type", "application/json"), ("X-Netfi-UI", "1"), ("Cookie", &cookie), ("Origin", &origin)];
        let (status, _, body) = self.http("POST", path, &headers, body);
        (status, body)
    }

    /// `GET /api/runs/ID` with the cookie: the run's status, if it exists.
    fn run_status(&self, id: &str) -> Option<serde_json::Value> {
        let (status, _, body) = self.http("GET", &format!("/api/runs/{id}"), &[("Cookie", &self.cookie())], "");
        (status == 200).then(|| serde_json::from_str(&body).unwrap())
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
    let _guard = machine::alone();
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

/// A run as the page starts it; its id.
fn start_run(server: &Server, duration_s: f64) -> String {
    let toml = serde_json::json!({ "toml": "name = \"n\"\n[[stage]]\npreset = \"Normal\"\n", "duration_s": duration_s, "seed": 1 });
    let (status, body) = server.post_as_the_page("/api/runs", &toml.to_string());
    assert_eq!(status, 200, "{body}");
    serde_json::from_str::<serde_json::Value>(&body).unwrap()["id"].as_str().unwrap().to_string()
}

/// Until the run has ended: its status.
fn wait_ended(server: &Server, id: &str) -> serde_json::Value {
    let t0 = Instant::now();
    loop {
        let s = server.run_status(id).expect("the run exists");
        if s["state"] != "running" {
            return s;
        }
        assert!(t0.elapsed() < Duration::from_secs(120), "the run never ended");
        std::thread::sleep(Duration::from_millis(200));
    }
}

/// A web server of another origin (`http://127.0.0.1:OTHER/`, the same site
/// as the UI's, so even a `SameSite=Strict` cookie goes along): it serves
/// `page` to every request until the test ends.
fn hostile_site(page: String) -> String {
    let listener = std::net::TcpListener::bind("127.0.0.1:0").unwrap();
    let origin = format!("http://{}", listener.local_addr().unwrap());
    std::thread::spawn(move || {
        for mut conn in listener.incoming().map_while(Result::ok) {
            let mut buf = [0u8; 4096];
            let _ = conn.read(&mut buf);
            let _ = write!(conn, "HTTP/1.1 200 OK\r\nContent-Type: text/html\r\nContent-Length: {}\r\nConnection: close\r\n\r\n{page}", page.len());
        }
    });
    origin
}

#[test]
fn a_page_of_another_origin_can_neither_stop_nor_start_a_run() {
    let Some(browser) = browser_or_skip() else { return };
    let _guard = machine::alone();
    let server = Server::start();
    // The user opened the UI: the browser holds its cookie.
    let tab = browser.new_tab().unwrap();
    tab.navigate_to(&server.url).unwrap().wait_until_navigated().unwrap();
    until(&tab, "document.querySelectorAll('#stages fieldset').length", 10);
    assert_eq!(js(&tab, "location.search"), "", "the token left the address bar");
    let id = start_run(&server, 8.0);
    let ui = format!("http://{}", server.addr);
    // The hostile page: a simple cross-origin POST with the cookie (no
    // preflight), a JSON one with the page's header (which needs one),
    // then a plain form post.
    let stop = format!("{ui}/api/runs/{id}/stop");
    let page = format!(
        r#"<!doctype html><title>hostile</title><body><pre id="out"></pre>
<form id="f" method="post" action="{stop}"><input name="x" value="1"></form>
<script>
(async () => {{
  const out = {{}};
  try {{
    await fetch("{stop}", {{ method: "POST", mode: "no-cors", credentials: "include", headers: {{ "content-type": "text/plain" }}, body: "{{}}" }});
    out.simple = "sent";
  }} catch (e) {{ out.simple = "failed: " + e; }}
  try {{
    const r = await fetch("{ui}/api/runs", {{ method: "POST", credentials: "include",
      headers: {{ "content-type": "application/json", "x-netfi-ui": "1" }},
      body: JSON.stringify({{ toml: "name = \"x\"\n[[stage]]\npreset = \"Normal\"\n", duration_s: 1, seed: 1 }}) }});
    out.preflighted = "answered " + r.status;
  }} catch (e) {{ out.preflighted = "blocked"; }}
  document.getElementById("out").textContent = JSON.stringify(out);
}})();
</script></body>"#
    );
    let site = hostile_site(page);
    let evil = browser.new_tab().unwrap();
    evil.navigate_to(&format!("{site}/")).unwrap().wait_until_navigated().unwrap();
    let out = until(&evil, "document.getElementById('out').textContent", 30).as_str().unwrap().to_string();
    let out: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(out["simple"], "sent", "the simple request left the browser: {out}");
    assert_eq!(out["preflighted"], "blocked", "the server must not grant a cross-origin JSON request: {out}");
    // The form post: the browser shows the server's refusal.
    js(&evil, "document.getElementById('f').submit()");
    let refusal = until(&evil, "location.href.includes('/stop') && document.body.innerText", 30).as_str().unwrap().to_string();
    assert!(refusal.contains("a form post or a simple request is refused"), "{refusal}");
    // None of it took: the run ends on its own, as it was started, and no
    // other run was started.
    let s = wait_ended(&server, &id);
    assert_eq!(s["state"], "done", "{s}");
    assert_ne!(s["report"]["stopped"], true, "the run was stopped: {}", s["report"]);
    let next = id.rsplit_once('-').map(|(p, n)| format!("{p}-{}", n.parse::<u64>().unwrap() + 1)).unwrap();
    assert!(server.run_status(&next).is_none(), "a run `{next}` was started by the hostile page");
}

#[test]
fn a_page_reaching_the_server_by_another_name_is_refused() {
    // evil.example resolves to this host, as a rebinding DNS server would
    // make it: the browser then sends the server's own requests with
    // `Host: evil.example:PORT`.
    let Some(browser) = browser_with_or_skip(&["--host-resolver-rules=MAP evil.example 127.0.0.1", "--disable-features=HttpsUpgrades"]) else { return };
    let server = Server::start();
    let tab = browser.new_tab().unwrap();
    // Even with the token, the wrong name is refused before anything else.
    tab.navigate_to(&format!("http://evil.example:{}/?token={}", server.port(), server.token)).unwrap().wait_until_navigated().unwrap();
    let text = js(&tab, "document.body.innerText").as_str().unwrap_or_default().to_string();
    assert!(text.contains("Host `evil.example:") && text.contains("is not this server's"), "{text}");
    // On the wire, with the cookie: a state change under another Host.
    let host = format!("evil.example:{}", server.port());
    let cookie = server.cookie();
    let (status, _, body) = server.http(
        "POST",
        "/api/runs",
        &[("Host", &host), ("Cookie", &cookie), ("Content-Type", "application/json"), ("X-Netfi-UI", "1")],
        r#"{"toml": "name = \"x\"\n[[stage]]\npreset = \"Normal\"\n", "duration_s": 1}"#,
    );
    assert_eq!(status, 403, "{body}");
    assert!(body.contains("is not this server's"), "{body}");
}

#[test]
fn without_its_token_the_server_serves_nothing_and_changes_nothing() {
    let server = Server::start();
    let cookie = server.cookie();
    // No token, a wrong one, and a wrong cookie: 401.
    for (path, headers) in [
        ("/", vec![]),
        ("/?token=0000", vec![]),
        ("/api/runs/x", vec![("Cookie", format!("netfi-ui-{}=0000", server.port()))]),
        ("/assets/app.js", vec![]),
    ] {
        let headers: Vec<(&str, &str)> = headers.iter().map(|(k, v)| (*k, v.as_str())).collect();
        let (status, _, body) = server.http("GET", path, &headers, "");
        assert_eq!(status, 401, "{path}: {body}");
        assert!(body.contains("needs its token"), "{body}");
    }
    // The printed URL: the token goes into an HttpOnly, same-site cookie
    // and out of the address.
    let (status, head, _) = server.http("GET", &format!("/?token={}", server.token), &[], "");
    assert_eq!(status, 303, "{head}");
    let head = head.to_ascii_lowercase();
    assert!(head.contains("location: /\r\n") || head.ends_with("location: /"), "{head}");
    let set_cookie = head.lines().find(|l| l.starts_with("set-cookie:")).unwrap_or_else(|| panic!("no cookie set: {head}"));
    assert!(set_cookie.contains(&cookie.to_ascii_lowercase()) && set_cookie.contains("httponly") && set_cookie.contains("samesite=strict"), "{set_cookie}");
    let (status, _, body) = server.http("GET", "/", &[("Cookie", &cookie)], "");
    assert_eq!(status, 200, "{body}");
    // With the cookie, a state change must still be the page's: JSON and
    // its header, from its origin.
    let stop = "/api/runs/nosuch/stop";
    for headers in [
        vec![("Cookie", cookie.as_str()), ("Content-Type", "application/x-www-form-urlencoded")],
        vec![("Cookie", cookie.as_str()), ("Content-Type", "text/plain")],
        vec![("Cookie", cookie.as_str()), ("Content-Type", "application/json")],
        vec![("Cookie", cookie.as_str()), ("Content-Type", "application/json"), ("X-Netfi-UI", "1"), ("Origin", "http://127.0.0.1:1")],
    ] {
        let (status, _, body) = server.http("POST", stop, &headers, "{}");
        assert_eq!(status, 403, "{headers:?}: {body}");
    }
    let (status, body) = server.post_as_the_page(stop, "{}");
    assert_eq!(status, 404, "the page's own request reaches the handler: {body}");
}

#[test]
fn a_server_off_loopback_needs_its_token() {
    // Without the token, any address but loopback is refused at start.
    let o = Command::new(env!("CARGO_BIN_EXE_netfi")).args(["ui", "--port", "0", "--bind", "0.0.0.0", "--no-token"]).output().unwrap();
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(!o.status.success() && err.contains("refuses to listen on 0.0.0.0:0 without its token"), "{err}");
    // With it (the default), it listens, and still asks for the token.
    let server = Server::start_with(&["--bind", "0.0.0.0"]);
    let (status, _, body) = server.http("GET", "/", &[], "");
    assert_eq!(status, 401, "{body}");
    let (status, _, _) = server.http("GET", "/", &[("Cookie", &server.cookie())], "");
    assert_eq!(status, 200);
}
mod screens;
