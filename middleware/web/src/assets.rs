//! The dashboard's page and its assets, built by Vite from `middleware/web/ui` into `ui/dist`
//! (kept in the repository: `scripts/ui-build` rebuilds it, CI checks it is what its
//! sources build) and embedded into the binary, so the gateway serves its dashboard
//! offline, from one file.
//!
//! A path that is not an asset gets the page (the views are the page's own routes); a
//! build without the front end (`ui/dist` removed) gets a page that says how to build it.

use axum::http::{header, Method, StatusCode, Uri};
use axum::response::{IntoResponse, Response};
use rust_embed::Embed;

use crate::server::{error, not_found};

#[derive(Embed)]
#[folder = "ui/dist/"]
#[allow_missing = true]
struct Ui;

/// Whether the front end was built into this binary.
pub fn built() -> bool {
    Ui::get("index.html").is_some()
}

const NOT_BUILT: &str = "<!doctype html><meta charset=utf-8><title>AutoPlug</title>\
<body style=\"font-family:sans-serif;max-width:40em;margin:3em auto\">\
<h1>AutoPlug gateway</h1><p>The dashboard's front end was not built into this binary. \
Run <code>scripts/ui-build</code> (it builds <code>middleware/web/ui</code> with npm), then build \
again. The live stream is at <code>/api/stream</code> meanwhile.</p>";

fn content_type(path: &str) -> &'static str {
    match path.rsplit('.').next() {
        Some("html") => "text/html; charset=utf-8",
        Some("js") => "text/javascript; charset=utf-8",
        Some("css") => "text/css; charset=utf-8",
        Some("svg") => "image/svg+xml",
        Some("png") => "image/png",
        Some("ico") => "image/x-icon",
        Some("json") | Some("webmanifest") => "application/json",
        Some("txt") => "text/plain; charset=utf-8",
        Some("woff2") => "font/woff2",
        _ => "application/octet-stream",
    }
}

/// GET of anything outside `/api`: an asset, or the page.
pub(crate) async fn serve(method: Method, uri: Uri) -> Response {
    let path = uri.path().trim_start_matches('/');
    if path.starts_with("api/") || path == "api" {
        return not_found(&uri);
    }
    if method != Method::GET && method != Method::HEAD {
        return error(
            StatusCode::METHOD_NOT_ALLOWED,
            format!("{method} is not allowed here"),
        );
    }
    if let Some(file) = (!path.is_empty()).then(|| Ui::get(path)).flatten() {
        // Vite names its assets by their content's hash: they never change.
        let cache = if path.starts_with("assets/") {
            "public, max-age=31536000, immutable"
        } else {
            "no-cache"
        };
        return (
            [
                (header::CONTENT_TYPE, content_type(path)),
                (header::CACHE_CONTROL, cache),
            ],
            file.data,
        )
            .into_response();
    }
    if path.starts_with("assets/") || path.contains('.') {
        return not_found(&uri);
    }
    let page = Ui::get("index.html");
    let body = page.map_or(NOT_BUILT.as_bytes().to_vec().into(), |f| f.data);
    (
        [
            (header::CONTENT_TYPE, "text/html; charset=utf-8"),
            (header::CACHE_CONTROL, "no-cache"),
        ],
        body,
    )
        .into_response()
}
