//! The page's server: HTTP on 127.0.0.1 only, every request carrying the session's
//! random token, the Host header one of the two names of this port (no other site's
//! page can reach it through a name that resolves here), nothing served but the
//! page and the asked frames, and a Content-Security-Policy that lets the page load
//! nothing from anywhere else. The page and its script are compiled in: it works
//! offline, with no build step.

use std::io::Read;

use serde::Deserialize;
use serde_json::json;
use tiny_http::{Header, Method, Request, Response, Server};
use travmap_core::error::{Error, Result};
use travmap_outputs::labels::Answer;
use travmap_outputs::rendering::encode_png;

use crate::session::{Progress, Session};
use crate::views::{Colouring, bird_eye, cell_in_image, frame_view};

const PAGE: &str = include_str!("page/index.html");
const SCRIPT: &str = include_str!("page/app.js");
const STYLE: &str = include_str!("page/style.css");
const ICON: &str = include_str!("page/icon.svg");

/// Answers are a few dozen bytes: a larger body is refused unread.
const MAX_BODY_BYTES: u64 = 4096;

/// A served session, as the command line reports it.
pub struct Served {
    /// The page's address, with its token: the one URL that opens it.
    pub url: String,
}

/// A token no other page can guess: 128 bits from the operating system's random
/// source.
fn new_token() -> Result<String> {
    let mut bytes = [0u8; 16];
    let path = std::path::Path::new("/dev/urandom");
    std::fs::File::open(path)
        .and_then(|mut f| f.read_exact(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Serves `session` on 127.0.0.1:`port` (0: a free port) until the page says it is
/// done; `on_ready` gets the page's URL once the server listens, `on_answer` the
/// progress after each answer. Returns the progress at the end.
pub fn serve(
    mut session: Session,
    port: u16,
    on_ready: impl FnOnce(&Served),
    mut on_answer: impl FnMut(&Progress),
) -> Result<Progress> {
    let server = Server::http(("127.0.0.1", port)).map_err(|e| {
        Error::Config(format!(
            "cannot serve the labelling page on 127.0.0.1:{port}: {e}"
        ))
    })?;
    let port = server
        .server_addr()
        .to_ip()
        .map(|address| address.port())
        .unwrap_or(port);
    let token = new_token()?;
    on_ready(&Served {
        url: format!("http://127.0.0.1:{port}/?token={token}"),
    });
    let hosts = [format!("127.0.0.1:{port}"), format!("localhost:{port}")];
    for mut request in server.incoming_requests() {
        let (reply, done) = match refusal(&request, &token, &hosts) {
            Some(refused) => (refused, false),
            None => match request_parts(&mut request) {
                Ok(parts) => route(parts, &mut session, &token, &mut on_answer),
                Err(refused) => (refused, false),
            },
        };
        // A page that went away mid-answer loses nothing: the answer is saved.
        let _ = request.respond(with_policy(reply));
        if done {
            break;
        }
    }
    Ok(session.progress())
}

/// A request's method, path, query and body.
struct Parts {
    method: Method,
    path: String,
    query: String,
    body: Vec<u8>,
}

/// The parts of `request`; refused when its body is larger than any answer.
fn request_parts(request: &mut Request) -> std::result::Result<Parts, Reply> {
    let url = request.url().to_string();
    let (path, query) = url.split_once('?').unwrap_or((&url, ""));
    let mut body = Vec::new();
    if request
        .body_length()
        .is_some_and(|n| n as u64 > MAX_BODY_BYTES)
    {
        return Err(text(413, "refused: an answer is a few dozen bytes"));
    }
    let read = request
        .as_reader()
        .take(MAX_BODY_BYTES + 1)
        .read_to_end(&mut body);
    if read.is_err() || body.len() as u64 > MAX_BODY_BYTES {
        return Err(text(413, "refused: an answer is a few dozen bytes"));
    }
    Ok(Parts {
        method: request.method().clone(),
        path: path.to_string(),
        query: query.to_string(),
        body,
    })
}

/// Why a request is refused before it is read (another Host, no token), if it is.
fn refusal(
    request: &Request,
    token: &str,
    hosts: &[String],
) -> Option<Response<std::io::Cursor<Vec<u8>>>> {
    let header = |name: &'static str| {
        request
            .headers()
            .iter()
            .find(|h| h.field.equiv(name))
            .map(|h| h.value.as_str().to_string())
    };
    if !header("Host").is_some_and(|host| hosts.contains(&host)) {
        return Some(text(
            421,
            "refused: this server answers only to its own address (127.0.0.1 or localhost on its port)",
        ));
    }
    let (_, query) = request.url().split_once('?').unwrap_or(("", ""));
    let given = header("X-Travmap-Token").or_else(|| query_value(query, "token"));
    match given {
        Some(given) if same_secret(given.as_bytes(), token.as_bytes()) => None,
        _ => Some(text(
            403,
            "refused: open the page at the address travmap label printed (it holds the session's token)",
        )),
    }
}

/// Compares two secrets in a time that does not depend on where they differ.
fn same_secret(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

fn query_value(query: &str, key: &str) -> Option<String> {
    query
        .split('&')
        .filter_map(|pair| pair.split_once('='))
        .find(|(k, _)| *k == key)
        .map(|(_, v)| v.to_string())
}

type Reply = Response<std::io::Cursor<Vec<u8>>>;

fn text(status: u16, body: &str) -> Reply {
    bytes(
        status,
        "text/plain; charset=utf-8",
        body.as_bytes().to_vec(),
    )
}

fn bytes(status: u16, content_type: &str, body: Vec<u8>) -> Reply {
    Response::from_data(body)
        .with_status_code(status)
        .with_header(header("Content-Type", content_type))
}

fn json_reply(value: &serde_json::Value) -> Reply {
    bytes(200, "application/json", value.to_string().into_bytes())
}

fn header(name: &str, value: &str) -> Header {
    Header::from_bytes(name.as_bytes(), value.as_bytes())
        .expect("header names and values are ASCII")
}

/// Every reply: nothing from elsewhere may load, nothing cached, the token never in
/// a Referer.
fn with_policy(reply: Reply) -> Reply {
    reply
        .with_header(header(
            "Content-Security-Policy",
            "default-src 'none'; script-src 'self'; style-src 'self'; img-src 'self'; connect-src 'self'; base-uri 'none'; form-action 'none'; frame-ancestors 'none'",
        ))
        .with_header(header("Cache-Control", "no-store"))
        .with_header(header("Referrer-Policy", "no-referrer"))
        .with_header(header("X-Content-Type-Options", "nosniff"))
}

/// An answer as the page posts it.
#[derive(Deserialize)]
struct Posted {
    frame: usize,
    cell: usize,
    /// `traversable`, `not_traversable`, `skip`, or null to take an answer back.
    answer: Option<Answer>,
}

/// The reply to an accepted request, and whether the session is over.
fn route(
    parts: Parts,
    session: &mut Session,
    token: &str,
    on_answer: &mut impl FnMut(&Progress),
) -> (Reply, bool) {
    let segments: Vec<&str> = parts.path.trim_matches('/').split('/').collect();
    let frame_of = |text: &str| {
        text.parse::<usize>()
            .ok()
            .filter(|&i| i < session.questions.frames.len())
    };
    let reply = match (&parts.method, segments.as_slice()) {
        (Method::Get, [""]) => bytes(
            200,
            "text/html; charset=utf-8",
            PAGE.replace("{{token}}", token).into_bytes(),
        ),
        (Method::Get, ["app.js"]) => bytes(
            200,
            "text/javascript; charset=utf-8",
            SCRIPT.as_bytes().to_vec(),
        ),
        (Method::Get, ["icon.svg"]) => bytes(200, "image/svg+xml", ICON.as_bytes().to_vec()),
        (Method::Get, ["style.css"]) => {
            bytes(200, "text/css; charset=utf-8", STYLE.as_bytes().to_vec())
        }
        (Method::Get, ["api", "session"]) => json_reply(&session_json(session)),
        (Method::Get, ["api", "frame", i]) => match frame_of(i) {
            Some(i) => json_reply(&json!(frame_view(&session.questions.frames[i]))),
            None => text(404, "no such frame"),
        },
        (Method::Get, ["api", "frame", i, "bev.png"]) => match frame_of(i) {
            Some(i) => {
                let colouring = match query_value(&parts.query, "colour").as_deref() {
                    Some("remission") => Colouring::Remission,
                    _ => Colouring::Height,
                };
                let image = bird_eye(&session.questions.frames[i], colouring);
                bytes(200, "image/png", encode_png(&image))
            }
            None => text(404, "no such frame"),
        },
        (Method::Get, ["api", "frame", i, "camera.png"]) => {
            match frame_of(i).and_then(|i| session.questions.frames[i].camera.as_ref()) {
                Some(camera) => bytes(200, "image/png", encode_png(&camera.image)),
                None => text(404, "no camera image"),
            }
        }
        (Method::Get, ["api", "frame", i, "cell", cell, "outline"]) => {
            let frame = frame_of(i);
            let cell = cell.parse::<usize>().ok();
            match (frame, cell) {
                (Some(frame), Some(cell))
                    if cell < session.questions.frames[frame].result.layout.cell_count() =>
                {
                    json_reply(&json!(cell_in_image(
                        &session.questions.frames[frame],
                        cell
                    )))
                }
                _ => text(404, "no such cell"),
            }
        }
        (Method::Post, ["api", "answer"]) => {
            return (answered(&parts.body, session, on_answer), false);
        }
        (Method::Post, ["api", "done"]) => return (json_reply(&json!(session.progress())), true),
        _ => text(404, "not found"),
    };
    (reply, false)
}

/// Records a posted answer (saved before the reply), or says why not.
fn answered(body: &[u8], session: &mut Session, on_answer: &mut impl FnMut(&Progress)) -> Reply {
    let posted: Posted = match serde_json::from_slice(body) {
        Ok(posted) => posted,
        Err(e) => return text(400, &format!("not an answer: {e}")),
    };
    match session.answer(posted.frame, posted.cell, posted.answer) {
        Ok(progress) => {
            on_answer(&progress);
            json_reply(&json!(progress))
        }
        Err(Error::Config(problem)) => text(400, &problem),
        // The labels file could not be written: the page must say so, not go on.
        Err(e) => text(500, &format!("the answer could not be saved: {e}")),
    }
}

/// What the page needs to start: the frames, the cells asked in order, the answers
/// given so far (a reopened session resumes) and the progress.
fn session_json(session: &Session) -> serde_json::Value {
    let frames: Vec<serde_json::Value> = (session.questions.frames.iter())
        .map(|f| {
            json!({
                "source": f.source,
                "frame": f.result.index,
                "has_camera": f.camera.is_some(),
            })
        })
        .collect();
    let asked: Vec<serde_json::Value> = (session.questions.cells.iter())
        .map(|c| json!({"frame": c.frame, "cell": c.cell, "margin": c.margin}))
        .collect();
    let answers: Vec<serde_json::Value> = (session.answers().iter())
        .map(|(&(frame, cell), answer)| json!({"frame": frame, "cell": cell, "answer": answer}))
        .collect();
    json!({
        "frames": frames,
        "asked": asked,
        "answers": answers,
        "progress": session.progress(),
    })
}
