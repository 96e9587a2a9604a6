//! `skydome serve`: serves the built phone app (a folder of static files) over HTTP for
//! development. `localhost` is a secure context, so the camera and the service worker work in a
//! browser on this machine; a phone needs HTTPS (see the README's "On the phone").
//!
//! The app is built by `crates/skydome-web/build.sh` into `target/skydome-web/app` (the
//! default `--dir`); it is a separate build (WebAssembly), which is why the files are served
//! from that folder rather than embedded in this binary.

use std::path::{Component, Path, PathBuf};

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
}

/// The top-level entry point for `skydome serve`: serves until interrupted.
pub fn run(a: Args, quiet: bool) -> Result<()> {
    if !a.dir.join("index.html").is_file() {
        bail!(
            "{}: no built app here (no index.html); build it with crates/skydome-web/build.sh",
            a.dir.display()
        );
    }
    let server = tiny_http::Server::http(&a.addr)
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("{}: cannot listen", a.addr))?;
    let shown = server
        .server_addr()
        .to_ip()
        .map_or_else(|| a.addr.clone(), |s| s.to_string());
    crate::out(&format!(
        "serving {} at http://{shown}/ (Ctrl-C stops)",
        a.dir.display()
    ));
    // One thread per request: a client that stops reading (a closed tab in the middle of the
    // .wasm) must not stall the others.
    for request in server.incoming_requests() {
        let dir = a.dir.clone();
        std::thread::spawn(move || {
            let response = respond(&dir, request.method(), request.url());
            if let Err(e) = request.respond(response) {
                crate::io::warn(quiet, &format!("cannot answer a request: {e}"));
            }
        });
    }
    Ok(())
}

type Response = tiny_http::Response<std::io::Cursor<Vec<u8>>>;

/// The response to `GET url` from the app folder `dir`: the file, or 404/405.
fn respond(dir: &Path, method: &tiny_http::Method, url: &str) -> Response {
    if !matches!(method, tiny_http::Method::Get | tiny_http::Method::Head) {
        return text(405, "method not allowed");
    }
    let Some(path) = resolve(dir, url) else {
        return text(404, "not found");
    };
    match std::fs::read(&path) {
        Ok(bytes) => with_header(
            with_header(
                tiny_http::Response::from_data(bytes),
                "Content-Type",
                content_type(&path),
            ),
            // The service worker does the caching; the server always sends the current file.
            "Cache-Control",
            "no-cache",
        ),
        Err(_) => text(404, "not found"),
    }
}

fn text(code: u16, body: &str) -> Response {
    with_header(
        tiny_http::Response::from_data(body.as_bytes().to_vec()).with_status_code(code),
        "Content-Type",
        "text/plain; charset=utf-8",
    )
}

fn with_header(r: Response, name: &str, value: &str) -> Response {
    match tiny_http::Header::from_bytes(name.as_bytes(), value.as_bytes()) {
        Ok(h) => r.with_header(h),
        Err(()) => r,
    }
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
