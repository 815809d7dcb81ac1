//! The HTTP API and WebSocket the page uses (and any other client with the token):
//!
//! | route | token | what |
//! |---|---|---|
//! | `GET /` (`?token=`) | — | the page; with a valid `?token=` it sets the page's cookie and redirects to `/` |
//! | `GET /api/status` | reading | the newest status (JSON) |
//! | `GET /api/events` | reading | the events kept, oldest first |
//! | `GET /api/history` | reading | the plot's last 30 s: `[t_s, deviation_mm, head_speed_mm_s]` |
//! | `GET /api/scene` | reading | the fixed scene (tracker, head model, coil) |
//! | `GET /api/config` | reading | the running configuration and the sections that may change live |
//! | `POST /api/params` | yes | a partial configuration (JSON); 400 `{"key", "error"}` when refused |
//! | `POST /api/hold`, `/api/resume`, `/api/stop` | yes | the operator's hold, resume, stop |
//! | `POST /api/calibrate` | yes | a calibration collection waiting for the go: start it (the arm moves); 409 otherwise |
//! | `POST /api/navigate` | yes | a navigation task (registration, pivot calibration) waiting for the go: start it; 409 otherwise |
//! | `GET /api/targets` | reading | the session's targets (name, position mm, approach axis) |
//! | `POST /api/target` | yes | `{"name": …}`: go to that target by a planned path while compensating; 409 with why when refused |
//! | `POST /api/freedrive`, `/api/handback` | yes | while held: free-drive (the arm yields to a hand); hand back to the loop from where the hand left it |
//! | `POST /api/teach` | yes | while held: the coil's pose on the head becomes the goal (and is written to the configuration file); 409 with why when refused |
//! | `GET /api/frame.png` | reading | the camera's newest IR frame with the pipeline's overlays (404 without a camera) |
//! | `GET /api/mri` | reading | the patient's MRI: whether there is one (`[head] mesh` a NIfTI), its extent and window, the landmarks, 10-20 positions and targets in it ([`crate::mri`]) |
//! | `GET /api/mri/slice.png?plane=axial\|coronal\|sagittal&x=&y=&z=[&lo=&hi=]` | reading | one slice through the point (RAS, mm), grey from `lo` to `hi` (default: the MRI's window); 404 without an MRI, 400 naming a bad parameter |
//! | `GET /ws` | reading | the status, 25 times a second, as JSON text messages |
//!
//! "Reading" needs the token unless the console listens on loopback ([`crate::auth`]). Every
//! POST takes its body (up to [`MAX_BODY`]) even where it means nothing: a body left unread
//! makes the HTTP server close the connection after its response, and a client that reuses the
//! connection meanwhile gets no answer. Every
//! request must name this console as its host; a browser's request from another origin is
//! refused. Bodies are limited to [`MAX_BODY`] before they are read.

use crate::auth::{Site, Token, token_cookie};
use crate::page;
use crate::state::Shared;
use axum::Router;
use axum::body::Bytes;
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, Query, State};
use axum::http::header::{CACHE_CONTROL, CONTENT_TYPE, LOCATION, SET_COOKIE};
use axum::http::{HeaderMap, StatusCode};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde_json::json;
use std::sync::Arc;

/// The largest request body taken, bytes (a partial configuration is a few hundred).
pub const MAX_BODY: usize = 64 * 1024;
/// The largest WebSocket message taken from a client, bytes (the page sends none).
const MAX_WS_MESSAGE: usize = 1024;

/// The server's state.
#[derive(Debug, Clone)]
pub struct Api {
    /// What the loop and the server share.
    pub shared: Arc<Shared>,
    /// The session's token.
    pub token: Token,
    /// Where the console listens.
    pub site: Site,
}

/// The router.
pub fn router(api: Api) -> Router {
    Router::new()
        .route("/", get(index))
        .route(
            "/console.js",
            get(|| async { asset("text/javascript", page::JS) }),
        )
        .route(
            "/console.css",
            get(|| async { asset("text/css", page::CSS) }),
        )
        .route("/api/status", get(status))
        .route("/api/events", get(events))
        .route("/api/history", get(history))
        .route("/api/scene", get(scene))
        .route("/api/config", get(config))
        .route("/api/frame.png", get(frame_png))
        .route("/api/mri", get(mri))
        .route("/api/mri/slice.png", get(mri_slice))
        .route("/api/params", post(params))
        .route("/api/hold", post(hold))
        .route("/api/resume", post(resume))
        .route("/api/stop", post(stop))
        .route("/api/teach", post(teach))
        .route("/api/targets", get(targets))
        .route("/api/target", post(target))
        .route("/api/freedrive", post(freedrive))
        .route("/api/handback", post(handback))
        .route("/api/calibrate", post(calibrate))
        .route("/api/navigate", post(navigate))
        .route("/ws", get(ws))
        .layer(DefaultBodyLimit::max(MAX_BODY))
        .with_state(api)
}

fn asset(content_type: &'static str, body: &'static str) -> Response {
    (
        [(CONTENT_TYPE, content_type), (CACHE_CONTROL, "no-cache")],
        body,
    )
        .into_response()
}

fn refuse(code: StatusCode, why: &str) -> Response {
    (code, axum::Json(json!({ "error": why }))).into_response()
}

impl Api {
    /// A request that only reads: this console's host and origin, and the token unless reading
    /// is open (loopback).
    #[allow(clippy::result_large_err)] // a refusal is a response, built once
    fn may_read(&self, headers: &HeaderMap) -> Result<(), Response> {
        if !self.site.same_origin(headers) {
            return Err(refuse(StatusCode::FORBIDDEN, "another host or origin"));
        }
        if self.site.open_reading() || self.token.carried_by(headers) {
            Ok(())
        } else {
            Err(refuse(StatusCode::UNAUTHORIZED, "the token is needed"))
        }
    }

    /// A request that changes something: this console's host and origin, and the token.
    #[allow(clippy::result_large_err)]
    fn may_change(&self, headers: &HeaderMap) -> Result<(), Response> {
        if !self.site.same_origin(headers) {
            return Err(refuse(StatusCode::FORBIDDEN, "another host or origin"));
        }
        if self.token.carried_by(headers) {
            Ok(())
        } else {
            Err(refuse(
                StatusCode::UNAUTHORIZED,
                "the token is needed: open the link mocomp printed, or send Authorization: Bearer TOKEN",
            ))
        }
    }
}

#[derive(Debug, serde::Deserialize)]
struct TokenQuery {
    token: Option<String>,
}

async fn index(
    State(api): State<Api>,
    headers: HeaderMap,
    Query(q): Query<TokenQuery>,
) -> Response {
    if !api.site.same_origin(&headers) {
        return refuse(StatusCode::FORBIDDEN, "another host or origin");
    }
    match q.token {
        // The link's token becomes the page's cookie, and leaves the address bar (and history).
        Some(t) if api.token.matches(&t) => (
            StatusCode::SEE_OTHER,
            [
                (SET_COOKIE, token_cookie(&api.token)),
                (LOCATION, "/".to_owned()),
            ],
        )
            .into_response(),
        Some(_) => refuse(StatusCode::UNAUTHORIZED, "wrong token"),
        None => match api.may_read(&headers) {
            Ok(()) => asset("text/html; charset=utf-8", page::HTML),
            Err(r) => r,
        },
    }
}

async fn status(State(api): State<Api>, headers: HeaderMap) -> Response {
    match api.may_read(&headers) {
        Ok(()) => axum::Json(api.shared.status()).into_response(),
        Err(r) => r,
    }
}

async fn events(State(api): State<Api>, headers: HeaderMap) -> Response {
    match api.may_read(&headers) {
        Ok(()) => axum::Json(api.shared.events()).into_response(),
        Err(r) => r,
    }
}

async fn history(State(api): State<Api>, headers: HeaderMap) -> Response {
    match api.may_read(&headers) {
        Ok(()) => axum::Json(api.shared.history()).into_response(),
        Err(r) => r,
    }
}

async fn scene(State(api): State<Api>, headers: HeaderMap) -> Response {
    match api.may_read(&headers) {
        Ok(()) => axum::Json(api.shared.scene()).into_response(),
        Err(r) => r,
    }
}

async fn mri(State(api): State<Api>, headers: HeaderMap) -> Response {
    match api.may_read(&headers) {
        Ok(()) => axum::Json(&api.shared.mri.json).into_response(),
        Err(r) => r,
    }
}

/// `GET /api/mri/slice.png`'s parameters.
#[derive(Debug, serde::Deserialize)]
struct SliceQuery {
    plane: String,
    x: f64,
    y: f64,
    z: f64,
    lo: Option<f32>,
    hi: Option<f32>,
}

async fn mri_slice(
    State(api): State<Api>,
    headers: HeaderMap,
    query: Result<Query<SliceQuery>, axum::extract::rejection::QueryRejection>,
) -> Response {
    if let Err(r) = api.may_read(&headers) {
        return r;
    }
    let Ok(Query(q)) = query else {
        return refuse(
            StatusCode::BAD_REQUEST,
            "plane (axial, coronal, sagittal), x, y, z (mm) and optionally lo, hi",
        );
    };
    let plane: mocomp_mri::slice::Plane = match q.plane.parse() {
        Ok(p) => p,
        Err(e) => return refuse(StatusCode::BAD_REQUEST, &e),
    };
    let m = &api.shared.mri.json;
    if !m.available {
        return refuse(StatusCode::NOT_FOUND, m.why.as_deref().unwrap_or("no MRI"));
    }
    let (lo, hi) = (q.lo.unwrap_or(m.window[0]), q.hi.unwrap_or(m.window[1]));
    for (key, v) in [
        ("x", q.x),
        ("y", q.y),
        ("z", q.z),
        ("lo", f64::from(lo)),
        ("hi", f64::from(hi)),
    ] {
        if !v.is_finite() {
            return refuse(
                StatusCode::BAD_REQUEST,
                &format!("{key}: not a finite number"),
            );
        }
    }
    if hi <= lo {
        return refuse(StatusCode::BAD_REQUEST, "hi must be above lo");
    }
    let shared = Arc::clone(&api.shared);
    // Sampling and encoding take milliseconds: off the server's thread.
    match tokio::task::spawn_blocking(move || {
        shared.mri.slice_png(plane, [q.x, q.y, q.z], (lo, hi))
    })
    .await
    {
        Ok(Ok(png)) => (
            [(CONTENT_TYPE, "image/png"), (CACHE_CONTROL, "no-store")],
            png,
        )
            .into_response(),
        Ok(Err(e)) => refuse(StatusCode::NOT_FOUND, &e),
        Err(_) => refuse(
            StatusCode::INTERNAL_SERVER_ERROR,
            "the slice could not be drawn",
        ),
    }
}

async fn config(State(api): State<Api>, headers: HeaderMap) -> Response {
    if let Err(r) = api.may_read(&headers) {
        return r;
    }
    axum::Json(json!({
        "config": api.shared.config(),
        "live_sections": mocomp_app::live::tuning::LIVE_SECTIONS,
        "authorized": api.token.carried_by(&headers),
    }))
    .into_response()
}

async fn params(State(api): State<Api>, headers: HeaderMap, body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    let patch: serde_json::Value = match serde_json::from_slice(&body) {
        Ok(v) => v,
        Err(e) => {
            return (
                StatusCode::BAD_REQUEST,
                axum::Json(json!({ "key": "(body)", "error": format!("not JSON: {e}") })),
            )
                .into_response();
        }
    };
    let tuned = match mocomp_app::live::tuning::apply(&api.shared.config(), &patch) {
        Ok(t) => t,
        Err(refusal) => {
            return (
                StatusCode::BAD_REQUEST,
                axum::Json(json!({ "key": refusal.key, "error": refusal.problem })),
            )
                .into_response();
        }
    };
    // The camera's section is the tracker's: the simulated camera's, or the Azure Kinect's.
    let (section, params) = match tuned.config.tracker.source {
        mocomp_app::config::TrackerSource::K4a => {
            ("tracker.k4a.params", tuned.config.tracker.k4a.params)
        }
        _ => ("tracker.camera.params", tuned.config.tracker.camera.params),
    };
    let camera_changed = tuned
        .changed
        .iter()
        .any(|k| k.starts_with("tracker.camera.params.") || k.starts_with("tracker.k4a.params."));
    let vision = api.shared.controls.vision();
    let other = tuned
        .changed
        .iter()
        .find(|k| k.starts_with("tracker.") && !k.starts_with(&format!("{section}.")));
    if camera_changed && (vision.is_none() || other.is_some()) {
        let source = tuned.config.tracker.source;
        let error = if vision.is_none() {
            format!("this session has no camera (tracker.source is \"{source}\")")
        } else {
            format!("this session's camera is [{section}] (tracker.source \"{source}\")")
        };
        return (
            StatusCode::CONFLICT,
            axum::Json(json!({ "key": other.map_or(section, String::as_str), "error": error })),
        )
            .into_response();
    }
    if tuned.changed.iter().any(|k| k.starts_with("loop."))
        && let Err(e) = api.shared.controls.tune(tuned.config.params)
    {
        return refuse(StatusCode::CONFLICT, &e.to_string());
    }
    if camera_changed
        && let Some(v) = vision
        && let Err(e) = v.set_params(params)
    {
        // Checked by the tuning already: this cannot refuse what it accepted.
        return refuse(StatusCode::BAD_REQUEST, &e.to_string());
    }
    let changed = tuned.changed.clone();
    api.shared.set_config(tuned.config);
    axum::Json(json!({ "changed": changed })).into_response()
}

async fn frame_png(State(api): State<Api>, headers: HeaderMap) -> Response {
    if let Err(r) = api.may_read(&headers) {
        return r;
    }
    let Some(vision) = api.shared.controls.vision().cloned() else {
        return refuse(StatusCode::NOT_FOUND, "this session has no camera");
    };
    // Drawing and encoding take milliseconds: off the server's thread.
    match tokio::task::spawn_blocking(move || vision.overlay_png()).await {
        Ok(Ok(Some(png))) => (
            [(CONTENT_TYPE, "image/png"), (CACHE_CONTROL, "no-store")],
            png,
        )
            .into_response(),
        Ok(Ok(None)) => refuse(StatusCode::NOT_FOUND, "no frame yet"),
        Ok(Err(e)) => refuse(StatusCode::INTERNAL_SERVER_ERROR, &e.to_string()),
        Err(_) => refuse(
            StatusCode::INTERNAL_SERVER_ERROR,
            "drawing the frame failed",
        ),
    }
}

/// The operator's hold (`true`) or resume: only while a loop runs.
fn set_hold(api: &Api, headers: &HeaderMap, hold: bool) -> Response {
    if let Err(r) = api.may_change(headers) {
        return r;
    }
    if api.shared.status().calibration.is_some() {
        return refuse(
            StatusCode::CONFLICT,
            "a calibration collection runs, not the loop: stop it instead",
        );
    }
    if hold {
        api.shared.controls.set_hold(true);
    } else {
        // A resume also re-arms a loop the controller stopped (its recovery, then a path).
        api.shared.controls.resume();
    }
    axum::Json(json!({ "operator_hold": hold })).into_response()
}

async fn hold(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    set_hold(&api, &headers, true)
}

async fn resume(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    set_hold(&api, &headers, false)
}

async fn stop(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    api.shared.controls.stop();
    axum::Json(json!({ "stopping": true })).into_response()
}

async fn targets(State(api): State<Api>, headers: HeaderMap) -> Response {
    if let Err(r) = api.may_read(&headers) {
        return r;
    }
    let list: Vec<_> = api
        .shared
        .controls
        .targets()
        .iter()
        .map(|(name, pose)| {
            let p = pose.translation.vector * 1e3;
            let axis = pose.rotation * mocomp_geom::nalgebra::Vector3::z();
            json!({ "name": name, "position_mm": [p.x, p.y, p.z], "axis": [axis.x, axis.y, axis.z] })
        })
        .collect();
    axum::Json(json!({ "targets": list })).into_response()
}

#[derive(Debug, serde::Deserialize)]
#[serde(deny_unknown_fields)]
struct TargetRequest {
    name: String,
}

async fn target(State(api): State<Api>, headers: HeaderMap, body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    let req: TargetRequest = match serde_json::from_slice(&body) {
        Ok(r) => r,
        Err(e) => return refuse(StatusCode::BAD_REQUEST, &format!("body: {e}")),
    };
    match mocomp_app::live::session::select_target(
        &api.shared.config(),
        &api.shared.controls,
        &req.name,
    ) {
        Ok(index) => axum::Json(json!({ "selected": req.name, "index": index })).into_response(),
        Err(e) => refuse(StatusCode::CONFLICT, &e.to_string()),
    }
}

fn set_freedrive(api: &Api, headers: &HeaderMap, on: bool) -> Response {
    if let Err(r) = api.may_change(headers) {
        return r;
    }
    match mocomp_app::live::session::set_freedrive(&api.shared.controls, on) {
        Ok(()) => axum::Json(json!({ "freedrive": on })).into_response(),
        Err(e) => refuse(StatusCode::CONFLICT, &e.to_string()),
    }
}

async fn freedrive(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    set_freedrive(&api, &headers, true)
}

async fn handback(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    set_freedrive(&api, &headers, false)
}

async fn calibrate(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    let waiting = api
        .shared
        .status()
        .calibration
        .is_some_and(|c| c.state == "waiting");
    if !waiting || api.shared.controls.start_requested() {
        return refuse(
            StatusCode::CONFLICT,
            "no calibration collection is waiting for the go (mocomp calibrate collect --dashboard)",
        );
    }
    api.shared.controls.request_start();
    axum::Json(json!({ "started": true })).into_response()
}

async fn navigate(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    let waiting = api
        .shared
        .status()
        .navigation
        .is_some_and(|n| n.state == "waiting");
    if !waiting || api.shared.controls.start_requested() {
        return refuse(
            StatusCode::CONFLICT,
            "no navigation task is waiting for the go (mocomp register --dashboard)",
        );
    }
    api.shared.controls.request_start();
    axum::Json(json!({ "started": true })).into_response()
}

async fn teach(State(api): State<Api>, headers: HeaderMap, _body: Bytes) -> Response {
    if let Err(r) = api.may_change(&headers) {
        return r;
    }
    if !api.shared.controls.hold() {
        return refuse(
            StatusCode::CONFLICT,
            "hold the loop first: the coil must stand still where the goal is to be",
        );
    }
    let shared = Arc::clone(&api.shared);
    // Averaging and the file's rewrite take a while: off the server's thread.
    let done = tokio::task::spawn_blocking(move || -> Result<serde_json::Value, String> {
        let setup = &shared.setup;
        let taught = mocomp_app::robot::teach::teach_live(setup, &shared.teach_window())
            .map_err(|e| e.to_string())?;
        shared
            .controls
            .set_goal(taught.head_from_coil)
            .map_err(|e| e.to_string())?;
        let pose = mocomp_geom::ur_pose_from_iso(&taught.head_from_coil);
        let mut config = shared.config();
        config.goal.head_from_coil = mocomp_app::config::Pose::try_from(pose).ok();
        shared.set_config(config);
        // Kept across restarts: the configuration file gets the goal, its comments kept.
        let written = match &setup.path {
            Some(path) => {
                mocomp_app::robot::teach::write_goal(path, &taught).map_err(|e| {
                    format!("the goal is in use, but writing it to the file failed: {e}")
                })?;
                Some(path.display().to_string())
            }
            None => None,
        };
        Ok(json!({
            "head_from_coil": pose,
            "distance_mm": taught.distance_m * 1e3,
            "spread_mm": taught.spread.0 * 1e3,
            "spread_deg": taught.spread.1.to_degrees(),
            "samples": taught.samples,
            "written": written,
        }))
    })
    .await;
    match done {
        Ok(Ok(v)) => axum::Json(v).into_response(),
        Ok(Err(why)) => refuse(StatusCode::CONFLICT, &why),
        Err(_) => refuse(StatusCode::INTERNAL_SERVER_ERROR, "teaching failed"),
    }
}

async fn ws(State(api): State<Api>, headers: HeaderMap, upgrade: WebSocketUpgrade) -> Response {
    if let Err(r) = api.may_read(&headers) {
        return r;
    }
    upgrade
        .max_message_size(MAX_WS_MESSAGE)
        .max_frame_size(MAX_WS_MESSAGE)
        .on_upgrade(move |socket| stream_status(socket, api))
}

/// Sends each status as it is published, until the client leaves or the loop has ended.
async fn stream_status(mut socket: WebSocket, api: Api) {
    let mut rx = api.shared.subscribe();
    let sent = api.shared.register_stream();
    loop {
        let published = rx.borrow_and_update().clone();
        if socket
            .send(Message::text(published.text.as_ref()))
            .await
            .is_err()
        {
            return;
        }
        sent.store(published.version, std::sync::atomic::Ordering::Release);
        tokio::select! {
            changed = rx.changed() => if changed.is_err() { return },
            incoming = socket.recv() => match incoming {
                // The page sends nothing; a close or an error ends the stream.
                Some(Ok(Message::Close(_)) | Err(_)) | None => return,
                Some(Ok(_)) => {}
            },
        }
    }
}
