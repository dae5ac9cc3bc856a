//! `travmap label` and `train --prior` (issue "teach it your robot"): the loop
//! without a person (answers from ground truth), the page's server answering only its
//! own address and token, every answer saved as it is given and resumed, and the
//! page driven in headless Chromium by click and by key.

use std::io::{BufRead, BufReader, Read, Write};
use std::net::TcpStream;
use std::path::Path;
use std::process::{Child, Command, Stdio};

use crate::common::{
    arg, assert_contains, clean_failure, json_summary, run_client, sample, shared_data, success,
    travmap,
};
use serde_json::Value;
use travmap_outputs::labels::{Answer, read_labels};

#[test]
fn the_loop_runs_without_a_person_and_teaches_a_model_checked_against_its_prior() {
    let Some(drive) = shared_data("semantickitti-07-000000/sequences/07") else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let labels = dir.path().join("labels.parquet");
    let summary = json_summary(&[
        "label",
        arg(&drive),
        "-o",
        arg(&labels),
        "--ask",
        "60",
        "--answers-from-ground-truth",
    ]);
    assert_eq!(summary["progress"]["asked"], 60, "{summary}");
    assert_eq!(summary["progress"]["answered"], 60);
    assert_eq!(summary["model"]["rule"], "road");
    // The file: a cell table of the answers (the labelled ones as rows), what was
    // asked in its metadata.
    let (answers, record) = read_labels(&labels).unwrap();
    assert_eq!(record.answered_by, "ground truth");
    assert_eq!(record.asked.len(), 60);
    let labelled = answers.iter().filter(|(_, a)| *a != Answer::Skip).count();
    assert_eq!(
        labelled as u64,
        summary["progress"]["labelled"].as_u64().unwrap()
    );
    // Asking twice asks the same cells: a reopened session resumes.
    let again = json_summary(&[
        "label",
        arg(&drive),
        "-o",
        arg(&labels),
        "--ask",
        "60",
        "--answers-from-ground-truth",
    ]);
    assert_eq!(again["progress"], summary["progress"]);
    // Taught with the embedded model's support vectors: checked on the labelled
    // cells, and a model every command takes.
    let model = dir.path().join("robot.json");
    let output = travmap(&["train", arg(&labels), "--prior", "road", "-o", arg(&model)]);
    let out = success(output);
    assert_contains(
        &out,
        &[
            "taught embedded road model: on your",
            "the prior scores mIoU",
            "the taught model",
        ],
    );
    assert_contains(&out, &["fit on the labelled drives:"]);
    let trained = json_summary(&["train", arg(&labels), "--prior", "road", "-o", arg(&model)]);
    let check = &trained["check"];
    assert!(
        check["taught_miou"].as_f64().unwrap() >= check["prior_miou"].as_f64().unwrap(),
        "{check}"
    );
    // How each fits the labelled drive, measured (said in one line above).
    let fit = &trained["fit"];
    for model in ["taught", "prior"] {
        assert_eq!(fit[model]["cells"], fit["prior"]["cells"], "{fit}");
        assert!(fit[model]["unsure_share"].as_f64().unwrap() > 0.0, "{fit}");
    }
    let scored = json_summary(&["eval", arg(&drive), "--model", arg(&model)]);
    assert!(scored["scores"]["miou"].as_f64().unwrap() > 0.5);
}

#[test]
fn answers_from_ground_truth_need_labels_and_a_labels_file_answers_its_own_questions() {
    let Some(drive) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let unlabelled = crate::common::without_labels(&drive, dir.path());
    let labels = dir.path().join("labels.parquet");
    let err = clean_failure(travmap(&[
        "label",
        arg(&unlabelled),
        "-o",
        arg(&labels),
        "--answers-from-ground-truth",
    ]));
    assert_contains(&err, &["needs labelled drives"]);
    // A file of other questions is refused, not overwritten.
    success(travmap(&[
        "label",
        arg(&drive),
        "-o",
        arg(&labels),
        "--ask",
        "10",
        "--answers-from-ground-truth",
        "-q",
    ]));
    let before = std::fs::read(&labels).unwrap();
    let err = clean_failure(travmap(&[
        "label",
        arg(&drive),
        "-o",
        arg(&labels),
        "--answers-from-ground-truth",
        "--model",
        "offroad",
    ]));
    assert_contains(&err, &["asked by another model", "-o"]);
    assert_eq!(std::fs::read(&labels).unwrap(), before);
}

/// `travmap label` serving its page, and where: its child process and address.
struct Page {
    child: Child,
    url: String,
    port: u16,
    token: String,
}

impl Page {
    fn start(drive: &Path, labels: &Path, ask: &str) -> Page {
        let mut child = Command::new(env!("CARGO_BIN_EXE_travmap"))
            .args(["label", arg(drive), "-o", arg(labels), "--ask", ask])
            .current_dir(env!("CARGO_MANIFEST_DIR"))
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .unwrap();
        let stderr = child.stderr.take().unwrap();
        let mut lines = BufReader::new(stderr).lines();
        let url = loop {
            let line = lines
                .next()
                .expect("travmap label says where its page is")
                .unwrap();
            if let Some(at) = line.find("http://") {
                break line[at..].split_whitespace().next().unwrap().to_string();
            }
        };
        // Keep draining stderr so the child never blocks on a full pipe.
        std::thread::spawn(move || lines.for_each(drop));
        let port = url["http://127.0.0.1:".len()..]
            .split('/')
            .next()
            .unwrap()
            .parse()
            .unwrap();
        let token = url.split("token=").nth(1).unwrap().to_string();
        Page {
            child,
            url,
            port,
            token,
        }
    }

    /// A raw HTTP/1.1 request: its status and body.
    fn request(
        &self,
        method: &str,
        path: &str,
        host: &str,
        token: Option<&str>,
        body: &str,
    ) -> (u16, String) {
        let mut stream = TcpStream::connect(("127.0.0.1", self.port)).unwrap();
        let token = token.map_or(String::new(), |t| format!("X-Travmap-Token: {t}\r\n"));
        write!(
            stream,
            "{method} {path} HTTP/1.1\r\nHost: {host}\r\n{token}Content-Length: {}\r\nConnection: close\r\n\r\n{body}",
            body.len()
        )
        .unwrap();
        let mut reply = String::new();
        stream.read_to_string(&mut reply).unwrap();
        let status = reply[9..12].parse().unwrap();
        let body = reply
            .split("\r\n\r\n")
            .nth(1)
            .unwrap_or_default()
            .to_string();
        (status, body)
    }

    fn get(&self, path: &str) -> (u16, String) {
        let host = format!("127.0.0.1:{}", self.port);
        self.request("GET", path, &host, Some(&self.token), "")
    }

    fn post(&self, path: &str, body: &str) -> (u16, String) {
        let host = format!("127.0.0.1:{}", self.port);
        self.request("POST", path, &host, Some(&self.token), body)
    }
}

impl Drop for Page {
    fn drop(&mut self) {
        let _ = self.child.kill();
        let _ = self.child.wait();
    }
}

#[test]
fn the_page_answers_only_its_address_and_token_and_saves_every_answer() {
    let Some(drive) = sample() else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let labels = dir.path().join("labels.parquet");
    let mut page = Page::start(&drive, &labels, "8");
    let own = format!("127.0.0.1:{}", page.port);
    // No token, a wrong one, another Host (a page of another site reaching this
    // port through a name of its own): refused.
    assert_eq!(page.request("GET", "/api/session", &own, None, "").0, 403);
    assert_eq!(
        page.request(
            "GET",
            "/api/session",
            &own,
            Some("0123456789abcdef0123456789abcdef"),
            ""
        )
        .0,
        403
    );
    let token = page.token.clone();
    assert_eq!(
        page.request("GET", "/api/session", "evil.example:80", Some(&token), "")
            .0,
        421
    );
    assert_eq!(page.request("GET", "/", &own, None, "").0, 403);
    // Nothing but the page and the drive's frames.
    for path in [
        "/../Cargo.toml",
        "/api/frame/99",
        "/etc/passwd",
        "/api/frame/0/camera.png",
    ] {
        assert_eq!(page.get(path).0, 404, "{path}");
    }
    let (status, html) = page.get(&format!("/?token={}", page.token));
    assert_eq!(status, 200);
    assert!(
        html.contains("travmap label") && !html.contains("http"),
        "the page names no other site"
    );
    let (_, session) = page.get("/api/session");
    let session: Value = serde_json::from_str(&session).unwrap();
    let asked = session["asked"].as_array().unwrap();
    assert_eq!(asked.len(), 8);
    // Answers saved at once: the file holds each as soon as it is acknowledged.
    let first = &asked[0];
    let answer = |a: &Value, label: &str| {
        format!(
            r#"{{"frame": {}, "cell": {}, "answer": {label}}}"#,
            a["frame"], a["cell"]
        )
    };
    assert_eq!(
        page.post("/api/answer", &answer(first, "\"traversable\""))
            .0,
        200
    );
    assert_eq!(
        page.post("/api/answer", &answer(&asked[1], "\"skip\"")).0,
        200
    );
    let (answers, _) = read_labels(&labels).unwrap();
    assert_eq!(answers.len(), 2);
    assert!(answers.iter().any(|(_, a)| *a == Answer::Traversable));
    assert!(answers.iter().any(|(_, a)| *a == Answer::Skip));
    // Malformed answers are refused, and so are bodies no answer needs.
    assert_eq!(page.post("/api/answer", "{").0, 400);
    assert_eq!(page.post("/api/answer", &"x".repeat(10_000)).0, 413);
    // Stopped from the page: the command ends and says what it wrote.
    assert_eq!(page.post("/api/done", "").0, 200);
    let status = page.child.wait().unwrap();
    assert!(status.success());
    // Reopened on the same drive and file: resumed.
    let page = Page::start(&drive, &labels, "8");
    let (_, session) = page.get("/api/session");
    let session: Value = serde_json::from_str(&session).unwrap();
    assert_eq!(session["progress"]["answered"], 2, "{session}");
}

#[test]
#[ignore = "needs the real clients: source .ci/clients.sh, then cargo test --release -- --ignored"]
fn a_person_answers_by_click_and_key_in_chromium_and_the_file_holds_exactly_that() {
    let Some(drive) = shared_data("rellis3d-000104/sequences/00") else {
        return;
    };
    let Some(python) = crate::common::env_var("TRAVMAP_CLIENT_PYTHON", "the client venv's python")
    else {
        return;
    };
    let Some(chromium) = crate::common::env_var(
        "TRAVMAP_CHROMIUM",
        "a Chromium binary (apt install chromium)",
    ) else {
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let labels = dir.path().join("labels.parquet");
    let page = Page::start(&drive, &labels, "12");
    let script = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/label_page.py");
    let shot = dir.path().join("page.png");
    let output = run_client(Command::new(&python).args([
        arg(&script),
        &page.url,
        arg(&shot),
        "--chromium",
        &chromium,
    ]));
    let measured: Value = serde_json::from_slice(&output.stdout).unwrap();
    assert_eq!(measured["ok"], true, "{measured}");
    // Every request the page made went to its own server.
    let own = format!("http://127.0.0.1:{}/", page.port);
    for url in measured["requests"].as_array().unwrap() {
        assert!(url.as_str().unwrap().starts_with(&own), "{url}");
    }
    assert!(
        measured["console"].as_array().unwrap().is_empty(),
        "{measured}"
    );
    // The file holds exactly the page's answers: traversable, not, can't tell, painted.
    let (answers, _) = read_labels(&labels).unwrap();
    let mut kinds: Vec<Answer> = answers.iter().map(|(_, a)| *a).collect();
    kinds.sort_by_key(|a| format!("{a:?}"));
    assert_eq!(
        kinds,
        [
            Answer::NotTraversable,
            Answer::Skip,
            Answer::Traversable,
            Answer::Traversable
        ]
    );
    assert_eq!(measured["answers"].as_array().unwrap().len(), 4);
    assert!(std::fs::metadata(&shot).unwrap().len() > 10_000);
    // pyarrow, DuckDB and Polars read the labels file alike (the script checks
    // that they agree row by row): its three labelled cells.
    drop(page);
    let reader = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/clients/read_parquet.py");
    let read = run_client(Command::new(&python).args([arg(&reader), arg(&labels), "0"]));
    let read: Value = serde_json::from_slice(&read.stdout).unwrap();
    assert_eq!(read["rows"], 3, "{read}");
    assert_contains(
        &read["metadata_keys"].to_string(),
        &["travmap.labels", "travmap.model", "travmap.config"],
    );
}
