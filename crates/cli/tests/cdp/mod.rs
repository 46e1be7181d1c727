//! A minimal Chrome DevTools Protocol client for the viewer's browser test: the system
//! Chromium in headless mode, driven over `--remote-debugging-pipe` (JSON messages ending in
//! a NUL byte, read by Chromium from its fd 3 and written to its fd 4; a shell maps those to
//! our stdin / stdout pipes). Only what the test needs: open a page, evaluate JavaScript,
//! take a screenshot. Replaces the headless_chrome crate, whose websocket and protocol
//! bindings cost ~3 min of CPU in every cold CI build (docs/performance.md "Build time").

use std::io::{BufRead, BufReader, Write};
use std::path::Path;
use std::process::{Child, ChildStdin, Command, Stdio};
use std::sync::mpsc::{channel, Receiver};
use std::time::{Duration, Instant};

use base64::Engine;
use serde_json::{json, Value};

pub struct Browser {
    child: Child,
    input: ChildStdin,
    output: Receiver<Value>,
    next_id: u64,
    session: String,
    timeout: Duration,
}

impl Browser {
    /// Start `chrome` headless (no sandbox, WebGL on SwiftShader) with a 1280×720 viewport
    /// and a fresh profile in `profile`, and attach to one blank page.
    pub fn launch(chrome: &Path, profile: &Path, timeout: Duration) -> Browser {
        let flags = [
            "--headless=new",
            "--no-sandbox",
            "--remote-debugging-pipe",
            "--use-angle=swiftshader",
            "--enable-unsafe-swiftshader",
            "--window-size=1280,720",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            "--no-first-run",
            "--no-default-browser-check",
        ];
        let mut child = Command::new("sh")
            .arg("-c")
            .arg(r#"exec "$0" "$@" 3<&0 4>&1 0</dev/null 1>/dev/null"#)
            .arg(chrome)
            .args(flags)
            .arg(format!("--user-data-dir={}", profile.display()))
            .arg("about:blank")
            .stdin(Stdio::piped())
            .stdout(Stdio::piped())
            .stderr(Stdio::null())
            .spawn()
            .expect("start Chromium");
        let input = child.stdin.take().unwrap();
        let mut reader = BufReader::new(child.stdout.take().unwrap());
        let (tx, output) = channel();
        std::thread::spawn(move || {
            let mut buf = Vec::new();
            while reader.read_until(0, &mut buf).is_ok_and(|n| n > 0) {
                buf.pop_if(|b| *b == 0);
                if let Ok(v) = serde_json::from_slice::<Value>(&buf) {
                    if tx.send(v).is_err() {
                        break;
                    }
                }
                buf.clear();
            }
        });
        let mut b = Browser {
            child,
            input,
            output,
            next_id: 0,
            session: String::new(),
            timeout,
        };
        let target = b.call("Target.createTarget", json!({ "url": "about:blank" }));
        let attached = b.call(
            "Target.attachToTarget",
            json!({ "targetId": target["targetId"], "flatten": true }),
        );
        b.session = attached["sessionId"].as_str().unwrap().to_string();
        b.call("Page.enable", json!({}));
        b
    }

    /// Send a command (to the page once attached) and wait for its result; events and other
    /// replies are skipped. A protocol error fails the test.
    pub fn call(&mut self, method: &str, params: Value) -> Value {
        self.next_id += 1;
        let id = self.next_id;
        let mut msg = json!({ "id": id, "method": method, "params": params });
        if !self.session.is_empty() {
            msg["sessionId"] = json!(self.session);
        }
        let mut bytes = serde_json::to_vec(&msg).unwrap();
        bytes.push(0);
        self.input.write_all(&bytes).expect("write to Chromium");
        self.input.flush().unwrap();
        let deadline = Instant::now() + self.timeout;
        loop {
            let left = deadline.saturating_duration_since(Instant::now());
            let v = self
                .output
                .recv_timeout(left)
                .unwrap_or_else(|e| panic!("no answer from Chromium to {method}: {e}"));
            if v["id"].as_u64() == Some(id) {
                if let Some(err) = v.get("error") {
                    panic!("Chromium refused {method}: {err}");
                }
                return v["result"].clone();
            }
        }
    }

    /// Evaluate `js` in the page (promises awaited) and return its value as JSON.
    pub fn eval(&mut self, js: &str) -> Value {
        let r = self.call(
            "Runtime.evaluate",
            json!({ "expression": js, "returnByValue": true, "awaitPromise": true }),
        );
        if let Some(ex) = r.get("exceptionDetails") {
            panic!("the page threw evaluating `{js}`: {ex}");
        }
        r["result"]["value"].clone()
    }

    /// Load `url` and wait until its document has loaded (a marker set on the old
    /// document's window tells the two apart).
    pub fn navigate(&mut self, url: &str) {
        self.eval("window.__cdpOldDocument = true");
        self.call("Page.navigate", json!({ "url": url }));
        let start = Instant::now();
        let check = "!window.__cdpOldDocument && document.readyState === 'complete'";
        while self.eval(check) != json!(true) {
            assert!(start.elapsed() < self.timeout, "{url} did not load");
            std::thread::sleep(Duration::from_millis(25));
        }
    }

    /// A PNG of the viewport.
    pub fn screenshot(&mut self) -> Vec<u8> {
        let r = self.call("Page.captureScreenshot", json!({ "format": "png" }));
        base64::engine::general_purpose::STANDARD
            .decode(r["data"].as_str().unwrap())
            .expect("base64 screenshot")
    }
}

impl Drop for Browser {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}
