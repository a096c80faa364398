//! The HTTP API besides the stream: the write actions (token required) and the files the
//! dashboard lists (trips, recordings, the firmware library).
//!
//! | method and path | what | token |
//! |---|---|---|
//! | `GET /api/info` | what this gateway can do: `{"write": bool, "control": bool, "fleet": bool, "live": bool}` | — |
//! | `POST /api/auth` | 204 if the bearer token is right, else 401 | checks it |
//! | `POST /api/ecus/{ecu}/flash` | flash the body (a signed image), or `?image=NAME` from the library | yes |
//! | `POST /api/ecus/{ecu}/clear-dtcs` | clear one ECU's trouble codes (`all`: every ECU's) | yes |
//! | `POST /api/ecus/{ecu}/reset-verdict` | the gateway's routines for that ECU start over (`all`: every ECU's) | yes |
//! | `POST /api/recording` | `{"on": true}` starts recording all traffic, `false` stops | yes |
//! | `POST /api/road` | `{"mu_left": 1.0, "mu_right": 0.2}`: the virtual road's friction | yes |
//! | `POST /api/road/start` | `{}`: the standing virtual car back to its start line | yes |
//! | `POST /api/road/steering` | `{"along_road": true}`: the simulator steers the virtual car along its road; `false`: the person does | yes |
//! | `POST /api/replay` | `{"action": "play"}`, `pause`, `{"action":"speed","speed":4}`, `{"action":"seek","t":30}` | yes |
//! | `GET /api/history?paths=A,B` | each signal's points since the session began (see [`crate::history`]): `{"t0": s, "width_s": s, "signals": {PATH: {"t": [...], "v": [...]}}}` | — |
//! | `GET /api/trace?after=N&limit=M` | the frames numbered after N (see [`crate::trace`]): `{"last": N, "missed": n, "frames": [[seq, t, id, flags, dlc, data, name, sender], ...]}` | — |
//! | `GET /api/dbc` | the DBC file the bus is decoded with (`autoplug.dbc`) | — |
//! | `GET /api/images` | the firmware library: name, bytes, ECU, version of each image | — |
//! | `GET /api/recordings`, `GET /api/recordings/{name}` | the recordings, and one to download | — |
//! | `POST /api/recordings/{name}/replay` | open it in a replay dashboard of its own: `{"port": N}` | yes |
//! | `GET /api/trips`, `GET /api/trips/{id}`, `GET /api/trips/{id}/series?signal=PATH` | the stored trips | — |
//! | `POST /api/fleet/consent` | `{"campaign": 7, "install": true}`: the driver's answer to the fleet's update offer | yes |
//! | `GET /api/fleet`, `GET /api/fleet/campaigns/{id}` | the fleet's campaigns in total, one campaign per vehicle (a server with a fleet database) | — |
//!
//! Every answer is JSON (a download aside); every error is `{"error": "..."}` with the
//! status that fits: 400 a malformed request, 401 no or a wrong token, 404 nothing of that
//! name, 409 the session refused (its reason), 413 too large, 503 busy.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Duration;

use axum::body::Bytes;
use axum::extract::rejection::{BytesRejection, JsonRejection};
use axum::extract::{DefaultBodyLimit, Path as UrlPath, Query, State};
use axum::http::{header, HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use axum::{Json, Router};
use serde::Deserialize;
use tokio::sync::oneshot;

use crate::control::{Action, Command, ReplayAction, SendError};
use crate::server::{error, token_matches, Shared};

/// Largest image the flash action takes: the F446RE's application slot is smaller.
pub const MAX_IMAGE_BYTES: usize = 512 * 1024;
/// Largest JSON body of the other actions.
const MAX_JSON_BYTES: usize = 4096;
/// How long an action waits for the session's answer (it answers between two frames).
const ANSWER_TIMEOUT: Duration = Duration::from_secs(5);
/// Rows of a trip's series at most in one answer.
const MAX_SERIES_POINTS: usize = 100_000;

/// A failed request: its status and what was wrong (answered as `{"error": ...}`).
pub(crate) struct ApiError(StatusCode, String);

impl ApiError {
    fn new(status: StatusCode, message: impl Into<String>) -> Self {
        Self(status, message.into())
    }
}

impl IntoResponse for ApiError {
    fn into_response(self) -> Response {
        error(self.0, self.1)
    }
}

pub(crate) fn routes() -> Router<Arc<Shared>> {
    Router::new()
        .route("/api/info", get(info))
        .route("/api/auth", post(auth))
        .route(
            "/api/ecus/{ecu}/flash",
            post(flash).layer(DefaultBodyLimit::max(MAX_IMAGE_BYTES)),
        )
        .route("/api/ecus/{ecu}/clear-dtcs", post(clear_dtcs))
        .route("/api/ecus/{ecu}/reset-verdict", post(reset_verdict))
        .route("/api/recording", post(recording))
        .route("/api/road", post(road))
        .route("/api/road/start", post(road_start))
        .route("/api/road/steering", post(road_steering))
        .route("/api/replay", post(replay))
        .route("/api/history", get(history))
        .route("/api/trace", get(trace))
        .route("/api/dbc", get(dbc))
        .route("/api/images", get(images))
        .route("/api/recordings", get(recordings))
        .route("/api/recordings/{name}", get(download))
        .route("/api/recordings/{name}/replay", post(replay_recording))
        .route("/api/trips", get(trips))
        .route("/api/trips/{id}", get(trip))
        .route("/api/trips/{id}/series", get(series))
        .route("/api/fleet/consent", post(consent))
        .route("/api/fleet", get(fleet_overview))
        .route("/api/fleet/campaigns/{id}", get(fleet_campaign))
        .layer(DefaultBodyLimit::max(MAX_JSON_BYTES))
}

async fn info(State(shared): State<Arc<Shared>>) -> Response {
    Json(serde_json::json!({
        "write": shared.config.token.is_some(),
        "control": shared.control.is_some(),
        "fleet": shared.config.fleet.is_some(),
        "live": shared.config.live,
        "version": env!("CARGO_PKG_VERSION"),
    }))
    .into_response()
}

/// The bearer token of a request, checked: `Err` is the answer to give instead.
fn authorize(shared: &Shared, headers: &HeaderMap) -> Result<(), ApiError> {
    if shared.config.token.is_none() {
        return Err(ApiError::new(
            StatusCode::FORBIDDEN,
            "this gateway takes no write actions (it was started without a token)",
        ));
    }
    let given = headers
        .get(header::AUTHORIZATION)
        .and_then(|v| v.to_str().ok())
        .and_then(|v| v.strip_prefix("Bearer "));
    match given {
        Some(token) if token_matches(&shared.config, token.trim()) => Ok(()),
        Some(_) => Err(ApiError::new(StatusCode::UNAUTHORIZED, "wrong token")),
        None => Err(ApiError::new(
            StatusCode::UNAUTHORIZED,
            "this action needs the token printed at the gateway's start (Authorization: Bearer TOKEN)",
        )),
    }
}

async fn auth(State(shared): State<Arc<Shared>>, headers: HeaderMap) -> Response {
    match authorize(&shared, &headers) {
        Ok(()) => StatusCode::NO_CONTENT.into_response(),
        Err(e) => e.into_response(),
    }
}

/// Hands an action to the session and waits for its answer.
async fn act(shared: &Shared, action: Action) -> Response {
    let Some(control) = shared.control.as_ref() else {
        return error(
            StatusCode::CONFLICT,
            "this gateway takes no commands (it only shows the bus)",
        );
    };
    // The session stands still with the car: an action would wait for the debugger.
    let halted = shared.table.halted_by_debugger();
    if !halted.is_empty() {
        return error(
            StatusCode::CONFLICT,
            format!(
                "the car is halted by the debugger ({}): continue it in GDB first",
                halted.join(", ")
            ),
        );
    }
    let (reply, answer) = oneshot::channel();
    match control.send(Command::Act { action, reply }) {
        Ok(()) => {}
        Err(SendError::Busy) => {
            return error(
                StatusCode::SERVICE_UNAVAILABLE,
                "the session is busy: try again",
            )
        }
        Err(SendError::Gone) => {
            return error(StatusCode::SERVICE_UNAVAILABLE, "the session has ended")
        }
    }
    match tokio::time::timeout(ANSWER_TIMEOUT, answer).await {
        Ok(Ok(Ok(value))) => Json(value).into_response(),
        Ok(Ok(Err(reason))) => error(StatusCode::CONFLICT, reason),
        Ok(Err(_)) => error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the session ended before it answered",
        ),
        Err(_) => error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the session did not answer in time",
        ),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct FlashQuery {
    image: Option<String>,
}

async fn flash(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    UrlPath(ecu): UrlPath<String>,
    query: Result<Query<FlashQuery>, axum::extract::rejection::QueryRejection>,
    body: Result<Bytes, BytesRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    let query = match query {
        Ok(Query(query)) => query,
        Err(e) => return error(StatusCode::BAD_REQUEST, format!("bad query: {e}")),
    };
    let body = match body {
        Ok(body) => body,
        Err(e) => {
            return error(
                e.status(),
                format!(
                    "the image could not be read: {} (at most {MAX_IMAGE_BYTES} bytes)",
                    e.body_text()
                ),
            )
        }
    };
    let (image, origin) = match query.image {
        Some(name) => {
            if !body.is_empty() {
                return error(
                    StatusCode::BAD_REQUEST,
                    "send an image in the body or name one with ?image=, not both",
                );
            }
            let Some(dir) = shared.config.images_dir.as_deref() else {
                return error(
                    StatusCode::NOT_FOUND,
                    "this gateway has no firmware library",
                );
            };
            let path = match file_in(dir, &name, &["img"]) {
                Ok(path) => path,
                Err(e) => return e.into_response(),
            };
            match read_limited(&path, MAX_IMAGE_BYTES).await {
                Ok(bytes) => (bytes, name),
                Err(e) => return e.into_response(),
            }
        }
        None if body.is_empty() => return error(
            StatusCode::BAD_REQUEST,
            "no image: send one in the body (application/octet-stream) or name one with ?image=",
        ),
        None => (body.to_vec(), "upload".to_string()),
    };
    act(&shared, Action::Flash { ecu, image, origin }).await
}

async fn clear_dtcs(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    UrlPath(ecu): UrlPath<String>,
) -> Response {
    for_ecus(&shared, &headers, ecu, |ecu| Action::ClearDtcs { ecu }).await
}

async fn reset_verdict(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    UrlPath(ecu): UrlPath<String>,
) -> Response {
    for_ecus(&shared, &headers, ecu, |ecu| Action::ResetVerdict { ecu }).await
}

/// An authorised action on one ECU, or on all nine (`all` in the path: `None`).
async fn for_ecus(
    shared: &Shared,
    headers: &HeaderMap,
    ecu: String,
    action: impl FnOnce(Option<String>) -> Action,
) -> Response {
    if let Err(e) = authorize(shared, headers) {
        return e.into_response();
    }
    act(shared, action((ecu != "all").then_some(ecu))).await
}

/// A JSON body, or the 400 that names what was wrong with it.
fn json_body<T>(body: Result<Json<T>, JsonRejection>) -> Result<T, ApiError> {
    body.map(|Json(v)| v)
        .map_err(|e| ApiError::new(e.status(), format!("bad request body: {}", e.body_text())))
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RecordingBody {
    on: bool,
}

async fn recording(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<RecordingBody>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(body) => act(&shared, Action::Record(body.on)).await,
        Err(e) => e.into_response(),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RoadBody {
    mu_left: f64,
    mu_right: f64,
}

async fn road(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<RoadBody>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(RoadBody { mu_left, mu_right }) => {
            act(&shared, Action::Road { mu_left, mu_right }).await
        }
        Err(e) => e.into_response(),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct EmptyBody {}

async fn road_start(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<EmptyBody>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(EmptyBody {}) => act(&shared, Action::RoadStart).await,
        Err(e) => e.into_response(),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SteeringBody {
    along_road: bool,
}

async fn road_steering(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<SteeringBody>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(SteeringBody { along_road }) => act(&shared, Action::RoadSteering(along_road)).await,
        Err(e) => e.into_response(),
    }
}

async fn replay(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<ReplayAction>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(action) => act(&shared, Action::Replay(action)).await,
        Err(e) => e.into_response(),
    }
}

/// `name` as a file directly in `dir` with one of `extensions`: no path separators, no
/// `..`, no hidden files; 404 if there is no such file.
fn file_in(dir: &Path, name: &str, extensions: &[&str]) -> Result<PathBuf, ApiError> {
    let plain = !name.is_empty()
        && name.len() <= 200
        && !name.starts_with('.')
        && name
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || matches!(c, '.' | '-' | '_'));
    let extension_ok = Path::new(name)
        .extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| extensions.contains(&e));
    if !plain || !extension_ok {
        return Err(ApiError::new(
            StatusCode::BAD_REQUEST,
            format!(
                "not a file name of this list: '{}' (letters, digits, . - _; ending in .{})",
                name.chars().take(60).collect::<String>(),
                extensions.join(" or .")
            ),
        ));
    }
    let path = dir.join(name);
    if !path.is_file() {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!("no file '{name}'"),
        ));
    }
    Ok(path)
}

async fn read_limited(path: &Path, max: usize) -> Result<Vec<u8>, ApiError> {
    let path = path.to_path_buf();
    let read = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, String> {
        let len = std::fs::metadata(&path).map_err(|e| e.to_string())?.len();
        if len > max as u64 {
            return Err(format!("{len} bytes, more than the {max} allowed"));
        }
        std::fs::read(&path).map_err(|e| e.to_string())
    })
    .await;
    match read {
        Ok(Ok(bytes)) => Ok(bytes),
        Ok(Err(why)) => Err(ApiError::new(
            StatusCode::CONFLICT,
            format!("cannot read it: {why}"),
        )),
        Err(_) => Err(ApiError::new(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the read failed",
        )),
    }
}

/// The files of `dir` with one of `extensions`: name, bytes, modified (Unix ms), newest
/// first; at most 1000.
fn list_files(dir: &Path, extensions: &[&str]) -> Result<Vec<(String, u64, u64)>, String> {
    let mut files = Vec::new();
    for entry in std::fs::read_dir(dir).map_err(|e| format!("{}: {e}", dir.display()))? {
        let Ok(entry) = entry else { continue };
        let Ok(meta) = entry.metadata() else { continue };
        let name = entry.file_name().to_string_lossy().into_owned();
        let ext_ok = Path::new(&name)
            .extension()
            .and_then(|e| e.to_str())
            .is_some_and(|e| extensions.contains(&e));
        if !meta.is_file() || !ext_ok || name.starts_with('.') {
            continue;
        }
        let modified = meta
            .modified()
            .ok()
            .and_then(|t| t.duration_since(std::time::UNIX_EPOCH).ok())
            .map_or(0, |d| d.as_millis() as u64);
        files.push((name, meta.len(), modified));
    }
    files.sort_by(|a, b| b.2.cmp(&a.2).then(a.0.cmp(&b.0)));
    files.truncate(1000);
    Ok(files)
}

async fn blocking<T: serde::Serialize + Send + 'static>(
    work: impl FnOnce() -> Result<T, ApiError> + Send + 'static,
) -> Response {
    match tokio::task::spawn_blocking(work).await {
        Ok(Ok(value)) => Json(value).into_response(),
        Ok(Err(e)) => e.into_response(),
        Err(_) => error(StatusCode::INTERNAL_SERVER_ERROR, "the request failed"),
    }
}

async fn images(State(shared): State<Arc<Shared>>) -> Response {
    let Some(dir) = shared.config.images_dir.clone() else {
        return Json(serde_json::json!([])).into_response();
    };
    blocking(move || {
        let files = list_files(&dir, &["img"])
            .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
        Ok(files
            .into_iter()
            .map(|(name, bytes, modified)| {
                let header = std::fs::File::open(dir.join(&name)).ok().and_then(|mut f| {
                    use std::io::Read;
                    let mut head = [0u8; autoplug_image::HEADER_LEN];
                    f.read_exact(&mut head).ok()?;
                    autoplug_image::ImageHeader::parse(&head).ok()
                });
                serde_json::json!({
                    "name": name,
                    "bytes": bytes,
                    "modified_ms": modified,
                    "node": header.as_ref().map(|h| h.node),
                    "version": header.as_ref().map(|h| h.version.to_string()),
                    "part_number": header.as_ref().map(|h| h.part_number.as_str().to_string()),
                    "variant": header.as_ref().map(|h| format!("{:?}", h.variant).to_lowercase()),
                })
            })
            .collect::<Vec<_>>())
    })
    .await
}

async fn recordings(State(shared): State<Arc<Shared>>) -> Response {
    let Some(dir) = shared.config.recordings_dir.clone() else {
        return Json(serde_json::json!([])).into_response();
    };
    blocking(move || {
        if !dir.exists() {
            return Ok(Vec::new());
        }
        let files = list_files(&dir, &["log"])
            .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))?;
        Ok(files
            .into_iter()
            .map(|(name, bytes, modified)| {
                serde_json::json!({ "name": name, "bytes": bytes, "modified_ms": modified })
            })
            .collect::<Vec<_>>())
    })
    .await
}

async fn download(State(shared): State<Arc<Shared>>, UrlPath(name): UrlPath<String>) -> Response {
    let Some(dir) = shared.config.recordings_dir.as_deref() else {
        return error(StatusCode::NOT_FOUND, "this gateway keeps no recordings");
    };
    let path = match file_in(dir, &name, &["log"]) {
        Ok(path) => path,
        Err(e) => return e.into_response(),
    };
    match tokio::fs::File::open(&path).await {
        Ok(file) => {
            let body = axum::body::Body::from_stream(tokio_util::io::ReaderStream::new(file));
            (
                [
                    (
                        header::CONTENT_TYPE,
                        "text/plain; charset=utf-8".to_string(),
                    ),
                    (
                        header::CONTENT_DISPOSITION,
                        format!("attachment; filename=\"{name}\""),
                    ),
                ],
                body,
            )
                .into_response()
        }
        Err(e) => error(StatusCode::NOT_FOUND, format!("cannot open '{name}': {e}")),
    }
}

async fn replay_recording(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    UrlPath(name): UrlPath<String>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    let Some(dir) = shared.config.recordings_dir.as_deref() else {
        return error(StatusCode::NOT_FOUND, "this gateway keeps no recordings");
    };
    match file_in(dir, &name, &["log"]) {
        Ok(path) => act(&shared, Action::ReplayRecording { path }).await,
        Err(e) => e.into_response(),
    }
}

/// Opens the trip database for reading (a second connection beside the gateway's, which
/// leaves its open trip alone).
fn open_store(shared: &Shared) -> Result<autoplug_store::SqliteStore, ApiError> {
    let Some(db) = shared.config.trips_db.as_deref() else {
        return Err(ApiError::new(
            StatusCode::NOT_FOUND,
            "this gateway keeps no trips",
        ));
    };
    if !db.exists() {
        return Err(ApiError::new(StatusCode::NOT_FOUND, "no trip database yet"));
    }
    autoplug_store::SqliteStore::open(db)
        .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))
}

async fn trips(State(shared): State<Arc<Shared>>) -> Response {
    blocking(move || {
        use autoplug_store::TripStore;
        let store = open_store(&shared)?;
        store
            .trips(None)
            .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))
    })
    .await
}

fn trip_id(text: &str) -> Result<autoplug_store::TripId, ApiError> {
    text.parse::<i64>()
        .map(autoplug_store::TripId)
        .map_err(|_| ApiError::new(StatusCode::BAD_REQUEST, "a trip id is a number"))
}

async fn trip(State(shared): State<Arc<Shared>>, UrlPath(id): UrlPath<String>) -> Response {
    blocking(move || {
        use autoplug_store::TripStore;
        let id = trip_id(&id)?;
        let store = open_store(&shared)?;
        match store.trip(id) {
            Ok(Some(detail)) => Ok(detail),
            Ok(None) => Err(ApiError::new(
                StatusCode::NOT_FOUND,
                format!("no trip {id}"),
            )),
            Err(e) => Err(ApiError::new(
                StatusCode::INTERNAL_SERVER_ERROR,
                e.to_string(),
            )),
        }
    })
    .await
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct SeriesQuery {
    signal: String,
}

async fn series(
    State(shared): State<Arc<Shared>>,
    UrlPath(id): UrlPath<String>,
    query: Result<Query<SeriesQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let signal = match query {
        Ok(Query(q)) => q.signal,
        Err(e) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!("name the signal: ?signal=Vehicle.Speed ({e})"),
            )
        }
    };
    blocking(move || {
        use autoplug_store::TripStore;
        let id = trip_id(&id)?;
        let store = open_store(&shared)?;
        let mut points = store
            .series(id, &signal)
            .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()))?;
        points.truncate(MAX_SERIES_POINTS);
        Ok(points)
    })
    .await
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct HistoryQuery {
    paths: String,
}

/// Signals asked for in one history request at most: the whole catalogue.
fn max_history_paths() -> usize {
    crate::LiveTable::catalog().len()
}

async fn history(
    State(shared): State<Arc<Shared>>,
    query: Result<Query<HistoryQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let paths = match query {
        Ok(Query(q)) => q.paths,
        Err(e) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!(
                "name the signals: ?paths=Vehicle.Speed,Vehicle.Chassis.Brake.PedalPosition ({e})"
            ),
            )
        }
    };
    let catalog = crate::LiveTable::catalog();
    let mut wanted = Vec::new();
    for path in paths.split(',').filter(|p| !p.is_empty()) {
        let Some(index) = catalog.iter().position(|s| s.path == path) else {
            return error(
                StatusCode::NOT_FOUND,
                format!(
                    "no signal {:?} in the catalogue",
                    crate::server::cut(path, 80)
                ),
            );
        };
        if !wanted.iter().any(|&(i, _)| i == index) {
            wanted.push((index, catalog[index].path));
        }
    }
    if wanted.is_empty() || wanted.len() > max_history_paths() {
        return error(
            StatusCode::BAD_REQUEST,
            "name one or more signals of the catalogue: ?paths=Vehicle.Speed",
        );
    }
    let table = shared.table.clone();
    let body = tokio::task::spawn_blocking(move || {
        use std::fmt::Write as _;
        let history = table.history();
        let (t0, width) = history.span();
        let mut json = String::from("{\"t0\":");
        match t0 {
            Some(t0) => {
                let _ = write!(json, "{t0:.6}");
            }
            None => json.push_str("null"),
        }
        let _ = write!(json, ",\"width_s\":{width},\"signals\":{{");
        for (k, (index, path)) in wanted.iter().enumerate() {
            if k > 0 {
                json.push(',');
            }
            let points = history.points(*index).unwrap_or_default();
            // VSS paths are dotted identifiers: nothing to escape.
            let _ = write!(json, "\"{path}\":{}", crate::history::points_json(&points));
        }
        json.push_str("}}");
        json
    })
    .await;
    match body {
        Ok(json) => ([(header::CONTENT_TYPE, "application/json")], json).into_response(),
        Err(e) => error(StatusCode::INTERNAL_SERVER_ERROR, e.to_string()),
    }
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct TraceQuery {
    #[serde(default)]
    after: u64,
    #[serde(default = "default_trace_limit")]
    limit: usize,
}

fn default_trace_limit() -> usize {
    500
}

async fn trace(
    State(shared): State<Arc<Shared>>,
    query: Result<Query<TraceQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    let q = match query {
        Ok(Query(q)) => q,
        Err(e) => {
            return error(
                StatusCode::BAD_REQUEST,
                format!(
                    "?after= takes the last frame number you have, ?limit= how many at most ({e})"
                ),
            )
        }
    };
    let page = shared.table.trace().after(q.after, q.limit);
    let mut json = format!(
        "{{\"last\":{},\"missed\":{},\"frames\":[",
        page.last, page.missed
    );
    json.push_str(&page.frames.join(","));
    json.push_str("]}");
    ([(header::CONTENT_TYPE, "application/json")], json).into_response()
}

async fn dbc() -> Response {
    (
        [
            (header::CONTENT_TYPE, "text/plain; charset=utf-8"),
            (
                header::CONTENT_DISPOSITION,
                "attachment; filename=\"autoplug.dbc\"",
            ),
        ],
        autoplug_can::DBC_FILE,
    )
        .into_response()
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ConsentBody {
    campaign: i64,
    install: bool,
}

async fn consent(
    State(shared): State<Arc<Shared>>,
    headers: HeaderMap,
    body: Result<Json<ConsentBody>, JsonRejection>,
) -> Response {
    if let Err(e) = authorize(&shared, &headers) {
        return e.into_response();
    }
    match json_body(body) {
        Ok(ConsentBody { campaign, install }) => {
            act(&shared, Action::CampaignConsent { campaign, install }).await
        }
        Err(e) => e.into_response(),
    }
}

/// Runs a fleet query off the event loop, one at a time (the database is shared with the
/// rest of the fleet: a flood of page loads queues here, it does not open connections).
async fn fleet_query<T: serde::Serialize + Send + 'static>(
    shared: &Arc<Shared>,
    query: impl FnOnce(&dyn crate::fleet::FleetData) -> Result<T, ApiError> + Send + 'static,
) -> Response {
    let Some(fleet) = shared.config.fleet.clone() else {
        return error(
            StatusCode::NOT_FOUND,
            "this server shows no fleet (start it with a fleet database: --fleet-db)",
        );
    };
    let Ok(Ok(permit)) =
        tokio::time::timeout(ANSWER_TIMEOUT, shared.fleet_queries.clone().acquire_owned()).await
    else {
        return error(
            StatusCode::SERVICE_UNAVAILABLE,
            "the fleet database is busy: try again",
        );
    };
    blocking(move || {
        let _permit = permit;
        query(fleet.as_ref())
    })
    .await
}

async fn fleet_overview(State(shared): State<Arc<Shared>>) -> Response {
    fleet_query(&shared, |fleet| {
        fleet
            .overview()
            .map_err(|e| ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e))
    })
    .await
}

async fn fleet_campaign(
    State(shared): State<Arc<Shared>>,
    UrlPath(id): UrlPath<String>,
) -> Response {
    let Ok(id) = id.parse::<i64>() else {
        return error(StatusCode::BAD_REQUEST, "a campaign id is a number");
    };
    fleet_query(&shared, move |fleet| match fleet.campaign(id) {
        Ok(Some(value)) => Ok(value),
        Ok(None) => Err(ApiError::new(
            StatusCode::NOT_FOUND,
            format!("no campaign {id}"),
        )),
        Err(e) => Err(ApiError::new(StatusCode::INTERNAL_SERVER_ERROR, e)),
    })
    .await
}
