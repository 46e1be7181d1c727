//! The viewer's HTTP server on 127.0.0.1: the page and renderer ([`super::assets`]),
//! `GET /api/meta` (JSON, [`super::meta`]) and `GET /api/splat?run=R&t=T[&colour=objects]`
//! (a run's Gaussians at time T, [`super::frames`]). A bad request gets a 4xx status and a
//! sentence saying what is wrong; a bug in a handler answers 500 and the server goes on.

use super::assets;
use super::frames::{Colouring, Frame, FrameSource};
use anyhow::{anyhow, Result};
use std::io::Cursor;
use std::net::TcpListener;
use std::panic::{catch_unwind, AssertUnwindSafe};
use std::sync::Arc;
use std::time::Instant;
use tiny_http::{Header, Method, Request, Response, StatusCode};

/// What the server serves: the runs (in pane order) and the metadata, serialized once.
pub struct Viewer {
    pub runs: Vec<FrameSource>,
    pub meta_json: String,
}

/// A request the viewer cannot answer, with the status and the reason the client sees.
#[derive(Debug, PartialEq)]
pub struct RequestError {
    pub status: u16,
    pub message: String,
}

fn bad(message: String) -> RequestError {
    RequestError {
        status: 400,
        message,
    }
}

fn not_found(message: String) -> RequestError {
    RequestError {
        status: 404,
        message,
    }
}

pub enum Reply {
    Asset(&'static assets::Asset),
    Json(String),
    Frame(Frame),
}

/// Serves requests on `threads` threads until the process ends.
pub fn serve(listener: TcpListener, viewer: Viewer, threads: usize) -> Result<()> {
    let server = tiny_http::Server::from_listener(listener, None)
        .map_err(|e| anyhow!("starting the HTTP server: {e}"))?;
    let server = Arc::new(server);
    let viewer = Arc::new(viewer);
    let workers: Vec<_> = (0..threads.max(1))
        .map(|_| {
            let (server, viewer) = (server.clone(), viewer.clone());
            std::thread::spawn(move || {
                for req in server.incoming_requests() {
                    respond(&viewer, req);
                }
            })
        })
        .collect();
    for w in workers {
        // A worker ends only when the server closes; a panic was already caught per request.
        let _ = w.join();
    }
    Ok(())
}

fn respond(v: &Viewer, req: Request) {
    let start = Instant::now();
    let url = req.url().to_string();
    let reply =
        catch_unwind(AssertUnwindSafe(|| route(v, req.method(), &url))).unwrap_or_else(|_| {
            Err(RequestError {
                status: 500,
                message: "the viewer failed on this request (a bug; see its log)".into(),
            })
        });
    let status = match &reply {
        Ok(_) => 200,
        Err(e) => e.status,
    };
    let result = match reply {
        Ok(r) => req.respond(response(r)),
        Err(e) => {
            tracing::warn!("{url}: {} {}", e.status, e.message);
            let body = format!("{}\n", e.message).into_bytes();
            let len = body.len();
            req.respond(Response::new(
                StatusCode(e.status),
                vec![header("Content-Type", "text/plain; charset=utf-8")],
                Cursor::new(body),
                Some(len),
                None,
            ))
        }
    };
    let ms = start.elapsed().as_secs_f64() * 1e3;
    tracing::debug!("{url}: {status} in {ms:.1} ms");
    if let Err(e) = result {
        tracing::debug!("{url}: the client went away ({e})");
    }
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes()).expect("ASCII header")
}

/// The bytes behind a response without copying them (a frame may be tens of MB).
enum Body {
    Static(&'static [u8]),
    Shared(Arc<Vec<u8>>),
}

impl AsRef<[u8]> for Body {
    fn as_ref(&self) -> &[u8] {
        match self {
            Body::Static(b) => b,
            Body::Shared(b) => b,
        }
    }
}

fn response(r: Reply) -> Response<Cursor<Body>> {
    let (content_type, body, mut extra) = match r {
        Reply::Asset(a) => (a.content_type, Body::Static(a.body), vec![]),
        Reply::Json(s) => (
            "application/json",
            Body::Shared(Arc::new(s.into_bytes())),
            vec![],
        ),
        Reply::Frame(f) => (
            "application/octet-stream",
            Body::Shared(f.bytes),
            vec![
                header("X-Frame-Cached", if f.cached { "1" } else { "0" }),
                header("X-Frame-Millis", &format!("{:.1}", f.millis)),
            ],
        ),
    };
    extra.push(header("Content-Type", content_type));
    // The page and frames change when the viewer restarts on other runs.
    extra.push(header("Cache-Control", "no-cache"));
    let len = body.as_ref().len();
    Response::new(StatusCode(200), extra, Cursor::new(body), Some(len), None)
}

pub fn route(v: &Viewer, method: &Method, url: &str) -> Result<Reply, RequestError> {
    if !matches!(method, Method::Get | Method::Head) {
        return Err(RequestError {
            status: 405,
            message: format!("{method} is not served: the viewer answers GET only"),
        });
    }
    let (path, query) = url.split_once('?').unwrap_or((url, ""));
    match path {
        "/api/meta" => Ok(Reply::Json(v.meta_json.clone())),
        "/api/splat" => splat(v, query).map(Reply::Frame),
        p => assets::find(p).map(Reply::Asset).ok_or_else(|| {
            not_found(format!(
                "no page `{p}`: the viewer serves /, /api/meta and /api/splat?run=R&t=T"
            ))
        }),
    }
}

/// `key=value` pairs of a query string (the last of a repeated key wins). Values are
/// numbers and words, so no percent-decoding: an encoded value fails to parse, clearly.
fn query_value<'a>(query: &'a str, key: &str) -> Option<&'a str> {
    query
        .split('&')
        .filter_map(|kv| kv.split_once('='))
        .rfind(|(k, _)| *k == key)
        .map(|(_, v)| v)
}

fn splat(v: &Viewer, query: &str) -> Result<Frame, RequestError> {
    let run = query_value(query, "run")
        .ok_or_else(|| bad("/api/splat needs run=R (0 for the first run)".into()))?;
    let n = v.runs.len();
    let index: usize = run.parse().map_err(|_| {
        bad(format!(
            "run={run} is not a run number ({n} run(s), from 0)"
        ))
    })?;
    let source = v.runs.get(index).ok_or_else(|| {
        not_found(format!(
            "no run {index}: this viewer shows {n} run(s), numbered from 0"
        ))
    })?;
    let t = query_value(query, "t").ok_or_else(|| bad("/api/splat needs t=T in [0, 1]".into()))?;
    let time: f32 = t
        .parse()
        .map_err(|_| bad(format!("t={t} is not a number")))?;
    if !(0.0..=1.0).contains(&time) {
        return Err(bad(format!("t={t} is outside [0, 1]")));
    }
    let colouring = match query_value(query, "colour").unwrap_or("rgb") {
        "rgb" => Colouring::Rgb,
        "objects" => Colouring::Objects,
        c => return Err(bad(format!("colour={c}: use rgb or objects"))),
    };
    if colouring == Colouring::Objects && !source.has_objects() {
        return Err(bad(format!(
            "run {index} has no object groups (it was trained without --objects), so \
             colour=objects does not apply"
        )));
    }
    Ok(source.frame(time, colouring))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn viewer() -> Viewer {
        Viewer {
            runs: vec![],
            meta_json: "{}".into(),
        }
    }

    fn err(url: &str) -> RequestError {
        match route(&viewer(), &Method::Get, url) {
            Err(e) => e,
            Ok(_) => panic!("{url} should fail"),
        }
    }

    #[test]
    fn serves_the_page_the_renderer_and_meta() {
        let v = viewer();
        for p in ["/", "/index.html", "/app.js", "/vendor/gsplat/index.es.js"] {
            assert!(
                matches!(route(&v, &Method::Get, p), Ok(Reply::Asset(_))),
                "{p}"
            );
        }
        assert!(matches!(
            route(&v, &Method::Get, "/api/meta?x=1"),
            Ok(Reply::Json(_))
        ));
    }

    #[test]
    fn bad_requests_get_a_status_and_a_reason() {
        assert_eq!(err("/nope").status, 404);
        assert!(err("/nope").message.contains("/api/splat"));
        assert_eq!(err("/api/splat?t=0.5").status, 400);
        assert_eq!(err("/api/splat?run=x&t=0.5").status, 400);
        let e = err("/api/splat?run=0&t=0.5");
        assert_eq!(e.status, 404, "{e:?}");
        let e = route(&viewer(), &Method::Post, "/").err().unwrap();
        assert_eq!(e.status, 405);
    }

    #[test]
    fn query_values() {
        assert_eq!(query_value("run=1&t=0.5&t=0.25", "t"), Some("0.25"));
        assert_eq!(query_value("run=1&x", "x"), None);
        assert_eq!(query_value("", "t"), None);
    }
}
