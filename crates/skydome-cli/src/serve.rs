//! `skydome serve`: serves the built phone app (a folder of static files) over HTTP for
//! development. `localhost` is a secure context, so the camera and the service worker work in a
//! browser on this machine; a phone needs HTTPS (see the README's "On the phone").
//!
//! The app is built by `crates/skydome-web/build.sh` into `target/skydome-web/app` (the
//! default `--dir`); it is a separate build (WebAssembly), which is why the files are served
//! from that folder rather than embedded in this binary.

use std::io::{Read, Write};
use std::net::{TcpListener, TcpStream};
use std::path::{Component, Path, PathBuf};
use std::time::Duration;

use anyhow::{bail, Context, Result};

/// Arguments of `skydome serve`.
#[derive(Debug, clap::Args)]
pub struct Args {
    /// Address and port to listen on.
    #[arg(long, default_value = "127.0.0.1:8080")]
    pub addr: String,
    /// The built app (the folder `crates/skydome-web/build.sh` writes).
    #[arg(long, default_value = "target/skydome-web/app")]
    pub dir: PathBuf,
    /// Send no cross-origin isolation headers (COOP/COEP), as a static host that cannot set
    /// headers does: the app then runs its single-threaded core (or its service worker adds the
    /// headers after the first visit; see docs/phone.md).
    #[arg(long)]
    pub no_isolation: bool,
}

/// The headers that make the page cross-origin isolated (`crossOriginIsolated` true,
/// `SharedArrayBuffer` available), which the app's threaded core needs: sent with every
/// response, as they must reach the page, its workers and the `.wasm` alike.
pub const ISOLATION_HEADERS: &str = "Cross-Origin-Opener-Policy: same-origin\r\n\
     Cross-Origin-Embedder-Policy: require-corp\r\nCross-Origin-Resource-Policy: same-origin\r\n";

/// The longest request head read (request line and headers); a browser's is under 2 KiB.
const MAX_HEAD: usize = 16 * 1024;

/// The top-level entry point for `skydome serve`: serves until interrupted.
///
/// Written on `std::net` with `httparse` rather than on an HTTP server crate: tiny_http 0.12
/// queued a new connection behind the browser's idle keep-alive connections now and then (its
/// thread pool can lose a wake-up while every thread holds a kept-alive connection), so a page
/// load hung for minutes. A static-file server for development needs GET/HEAD only; here every
/// connection has its own thread and is closed after one response, so no client can hold up
/// another.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    if !a.dir.join("index.html").is_file() {
        bail!(
            "{}: no built app here (no index.html); build it with crates/skydome-web/build.sh",
            a.dir.display()
        );
    }
    let listener =
        TcpListener::bind(&a.addr).with_context(|| format!("{}: cannot listen", a.addr))?;
    let shown = listener
        .local_addr()
        .map_or_else(|_| a.addr.clone(), |s| s.to_string());
    crate::out(&format!(
        "serving {} at http://{shown}/ (Ctrl-C stops)",
        a.dir.display()
    ));
    serve_on(&listener, &a.dir, !a.no_isolation, quiet);
    Ok(())
}

/// Answers connections on `listener` with files from `dir`, each on its own thread, forever;
/// with [`ISOLATION_HEADERS`] when `isolate`.
fn serve_on(listener: &TcpListener, dir: &Path, isolate: bool, quiet: bool) {
    for stream in listener.incoming() {
        let stream = match stream {
            Ok(s) => s,
            Err(e) => {
                crate::io::warn(quiet, &format!("cannot accept a connection: {e}"));
                continue;
            }
        };
        let dir = dir.to_path_buf();
        std::thread::spawn(move || {
            if let Err(e) = answer(&dir, stream, isolate) {
                crate::io::warn(quiet, &format!("cannot answer a request: {e}"));
            }
        });
    }
}

/// Reads one request from `stream` and writes its response, then closes the connection.
/// A client that connects and sends nothing (a browser's speculative connection) is dropped
/// after the read timeout.
fn answer(dir: &Path, mut stream: TcpStream, isolate: bool) -> std::io::Result<()> {
    stream.set_read_timeout(Some(Duration::from_secs(30)))?;
    stream.set_write_timeout(Some(Duration::from_secs(60)))?;
    let mut head = Vec::with_capacity(2048);
    let mut chunk = [0u8; 2048];
    let (method, url) = loop {
        let n = match stream.read(&mut chunk) {
            Ok(0) => return Ok(()),
            Ok(n) => n,
            Err(e) if is_timeout(&e) => return Ok(()),
            Err(e) => return Err(e),
        };
        head.extend_from_slice(&chunk[..n]);
        let mut headers = [httparse::EMPTY_HEADER; 64];
        let mut req = httparse::Request::new(&mut headers);
        match req.parse(&head) {
            Ok(httparse::Status::Complete(_)) => {
                break (
                    req.method.unwrap_or("").to_string(),
                    req.path.unwrap_or("/").to_string(),
                );
            }
            Ok(httparse::Status::Partial) if head.len() < MAX_HEAD => {}
            _ => {
                let (status, body) = text(400, "bad request");
                return write_response(&mut stream, status, body, true, isolate);
            }
        }
    };
    let (status, body) = respond(dir, &method, &url);
    write_response(&mut stream, status, body, method != "HEAD", isolate)
}

fn is_timeout(e: &std::io::Error) -> bool {
    matches!(
        e.kind(),
        std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
    )
}

/// A response: status code, then the body with its content type.
type Response = (u16, (&'static str, Vec<u8>));

fn write_response(
    stream: &mut TcpStream,
    status: u16,
    (content_type, bytes): (&'static str, Vec<u8>),
    with_body: bool,
    isolate: bool,
) -> std::io::Result<()> {
    let reason = match status {
        200 => "OK",
        400 => "Bad Request",
        404 => "Not Found",
        405 => "Method Not Allowed",
        _ => "",
    };
    // The service worker does the caching; the server always sends the current file.
    let head = format!(
        "HTTP/1.1 {status} {reason}\r\nContent-Type: {content_type}\r\nContent-Length: {}\r\n\
         Cache-Control: no-cache\r\nConnection: close\r\n{}\r\n",
        bytes.len(),
        if isolate { ISOLATION_HEADERS } else { "" }
    );
    stream.write_all(head.as_bytes())?;
    if with_body {
        stream.write_all(&bytes)?;
    }
    stream.flush()?;
    stream.shutdown(std::net::Shutdown::Write)
}

/// The response to `method url` from the app folder `dir`: the file, or 404/405.
fn respond(dir: &Path, method: &str, url: &str) -> Response {
    if !matches!(method, "GET" | "HEAD") {
        return text(405, "method not allowed");
    }
    let Some(path) = resolve(dir, url) else {
        return text(404, "not found");
    };
    match std::fs::read(&path) {
        Ok(bytes) => (200, (content_type(&path), bytes)),
        Err(_) => text(404, "not found"),
    }
}

fn text(code: u16, body: &str) -> Response {
    (
        code,
        ("text/plain; charset=utf-8", body.as_bytes().to_vec()),
    )
}

/// The file under `dir` for a request path (query dropped, `/` → `index.html`); `None` for a
/// path that would leave `dir` or names no file.
fn resolve(dir: &Path, url: &str) -> Option<PathBuf> {
    let path = url.split(['?', '#']).next().unwrap_or("");
    let rel = Path::new(path.trim_start_matches('/'));
    if rel.components().any(|c| !matches!(c, Component::Normal(_))) {
        return None;
    }
    let mut full = dir.join(rel);
    if full.is_dir() {
        full = full.join("index.html");
    }
    full.is_file().then_some(full)
}

/// MIME type by extension; `.wasm` must be `application/wasm` for streaming compilation.
fn content_type(path: &Path) -> &'static str {
    match path
        .extension()
        .and_then(|e| e.to_str())
        .unwrap_or("")
        .to_ascii_lowercase()
        .as_str()
    {
        "html" => "text/html; charset=utf-8",
        "js" | "mjs" => "text/javascript; charset=utf-8",
        "css" => "text/css; charset=utf-8",
        "json" => "application/json",
        "webmanifest" => "application/manifest+json",
        "wasm" => "application/wasm",
        "svg" => "image/svg+xml",
        "png" => "image/png",
        "jpg" | "jpeg" => "image/jpeg",
        _ => "application/octet-stream",
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn get(addr: std::net::SocketAddr, request: &str) -> String {
        let mut c = TcpStream::connect(addr).expect("connect");
        c.set_read_timeout(Some(Duration::from_secs(20)))
            .expect("timeout");
        c.write_all(request.as_bytes()).expect("send");
        let mut out = Vec::new();
        c.read_to_end(&mut out)
            .expect("a response before the timeout");
        String::from_utf8_lossy(&out).into_owned()
    }

    #[test]
    fn idle_connections_hold_up_no_request() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("index.html"), "<!doctype html>").expect("write");
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let addr = listener.local_addr().expect("addr");
        let d = dir.path().to_path_buf();
        std::thread::spawn(move || serve_on(&listener, &d, true, true));
        // A browser opens connections it may never use; they must not block the others.
        let idle: Vec<TcpStream> = (0..12)
            .map(|_| TcpStream::connect(addr).expect("connect"))
            .collect();
        for _ in 0..3 {
            let r = get(
                addr,
                "GET / HTTP/1.1\r\nHost: x\r\nConnection: keep-alive\r\n\r\n",
            );
            assert!(r.starts_with("HTTP/1.1 200 OK\r\n"), "{r}");
            assert!(
                r.contains("Content-Type: text/html; charset=utf-8\r\n"),
                "{r}"
            );
            assert!(r.contains("Connection: close\r\n"), "{r}");
            // Cross-origin isolated, for the threaded core (and on every response).
            assert!(
                r.contains("Cross-Origin-Opener-Policy: same-origin\r\n")
                    && r.contains("Cross-Origin-Embedder-Policy: require-corp\r\n"),
                "{r}"
            );
            assert!(r.ends_with("\r\n\r\n<!doctype html>"), "{r}");
        }
        let head = get(addr, "HEAD /index.html HTTP/1.1\r\nHost: x\r\n\r\n");
        assert!(head.contains("Content-Length: 15\r\n") && head.ends_with("\r\n\r\n"));
        let missing = get(addr, "GET /nothing.js HTTP/1.1\r\nHost: x\r\n\r\n");
        assert!(
            missing.starts_with("HTTP/1.1 404 Not Found\r\n"),
            "{missing}"
        );
        let post = get(
            addr,
            "POST / HTTP/1.1\r\nHost: x\r\nContent-Length: 0\r\n\r\n",
        );
        assert!(post.starts_with("HTTP/1.1 405 "), "{post}");
        let junk = get(addr, "\x01\x02 nonsense\r\n\r\n");
        assert!(junk.starts_with("HTTP/1.1 400 "), "{junk}");
        drop(idle);

        // --no-isolation: the same files without the headers.
        let listener = TcpListener::bind("127.0.0.1:0").expect("bind");
        let addr = listener.local_addr().expect("addr");
        let d = dir.path().to_path_buf();
        std::thread::spawn(move || serve_on(&listener, &d, false, true));
        let r = get(addr, "GET / HTTP/1.1\r\nHost: x\r\n\r\n");
        assert!(r.starts_with("HTTP/1.1 200 OK\r\n"), "{r}");
        assert!(!r.contains("Cross-Origin-"), "{r}");
    }

    #[test]
    fn paths_stay_inside_the_app_folder() {
        let dir = tempfile::tempdir().expect("tempdir");
        std::fs::write(dir.path().join("index.html"), "<!doctype html>").expect("write");
        std::fs::create_dir(dir.path().join("pkg")).expect("mkdir");
        std::fs::write(dir.path().join("pkg/a.wasm"), [0u8, 97, 115, 109]).expect("write");
        assert_eq!(
            resolve(dir.path(), "/"),
            Some(dir.path().join("index.html"))
        );
        assert_eq!(
            resolve(dir.path(), "/pkg/a.wasm?v=1"),
            Some(dir.path().join("pkg/a.wasm"))
        );
        assert_eq!(resolve(dir.path(), "/../Cargo.toml"), None);
        assert_eq!(resolve(dir.path(), "/pkg/../../x"), None);
        assert_eq!(resolve(dir.path(), "/missing.js"), None);
        assert_eq!(content_type(Path::new("x.wasm")), "application/wasm");
        assert_eq!(
            content_type(Path::new("app.JS")),
            "text/javascript; charset=utf-8"
        );
    }
}
