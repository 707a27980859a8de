//! The HTTP and WebSocket server (axum on tokio): the embedded page, one WebSocket per page,
//! downloads and uploads, behind the [`security`](crate::security) rules.
//!
//! Routes, all under `/TOKEN/`: `GET /` (the page), `GET /app/{file}` (its modules and
//! style), `GET /ws` (the WebSocket), `GET /download/{id}/{file}` (an object exported in the
//! format the file name's extension names), `POST /upload/{file}` (a file for the upload
//! root, at most [`Config::upload_limit`] bytes). Anything else, and a wrong token, is 403.

use std::net::{Ipv4Addr, SocketAddr};
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, RwLock};

use axum::Router;
use axum::body::{Body, Bytes};
use axum::extract::ws::{Message, WebSocket, WebSocketUpgrade};
use axum::extract::{DefaultBodyLimit, Path, Query, Request, State};
use axum::http::{HeaderMap, StatusCode, header};
use axum::middleware::{self, Next};
use axum::response::{IntoResponse, Response};
use axum::routing::{get, post};
use serde_json::{Value, json};
use tokio::sync::{broadcast, mpsc};
use volmorph_scene::{ObjectId, Scene};

use crate::coalesce::Queue;
use crate::jobs::{Editor, Job, JobProgress, Origin, Outgoing, Running, Work};
use crate::protocol::{Frame, FrameError, Kind, MAX_CLIENT_FRAME, VERSION};
use crate::security::{self, Roots};
use crate::views::{self, Caches, QueryError, u64_field, vec3_field};
use crate::{StudioError, assets, command_json};
use volmorph_scene::setup::Setup;

/// How the studio is started.
#[derive(Debug, Clone)]
pub struct Config {
    /// Files opened at start (each becomes an object named after its file).
    pub files: Vec<PathBuf>,
    /// Folders the page may read and write (the file browser, save, export).
    pub roots: Vec<PathBuf>,
    /// Port on 127.0.0.1 (0: any free port).
    pub port: u16,
    /// Largest upload, bytes.
    pub upload_limit: usize,
    /// Built-in set-ups run at start (e.g. the teapot with a lattice).
    pub setups: Vec<Setup>,
}

/// Default [`Config::upload_limit`]: 512 MiB.
pub const DEFAULT_UPLOAD_LIMIT: usize = 512 << 20;

pub(crate) struct Shared {
    pub port: u16,
    pub scene: Arc<RwLock<Scene>>,
    pub queue: Arc<Queue<Job>>,
    pub out: broadcast::Sender<Outgoing>,
    pub caches: Caches,
    pub running: Arc<Running>,
    pub roots: Roots,
    pub upload_dir: PathBuf,
    pub next_page: AtomicU64,
}

/// A running studio.
pub struct Studio {
    addr: SocketAddr,
    token: String,
    shared: Arc<Shared>,
    server: tokio::task::JoinHandle<()>,
    ticker: tokio::task::JoinHandle<()>,
}

impl Studio {
    /// The address it listens on (127.0.0.1).
    #[must_use]
    pub fn addr(&self) -> SocketAddr {
        self.addr
    }

    /// The launch token.
    #[must_use]
    pub fn token(&self) -> &str {
        &self.token
    }

    /// The page's URL, token included.
    #[must_use]
    pub fn url(&self) -> String {
        format!("http://{}/{}/", self.addr, self.token)
    }

    /// Wait until the server stops (it runs until the process ends).
    ///
    /// # Errors
    /// When the server task panicked.
    pub async fn wait(mut self) -> Result<(), StudioError> {
        (&mut self.server)
            .await
            .map_err(|e| StudioError::Server(e.to_string()))
    }
}

impl Drop for Studio {
    fn drop(&mut self) {
        self.server.abort();
        self.ticker.abort();
        self.shared.queue.close();
        let _ = std::fs::remove_dir_all(&self.shared.upload_dir);
    }
}

/// Start the studio: load the files, bind 127.0.0.1, start the editor thread and serve.
///
/// # Errors
/// [`StudioError`] for a file that cannot be read, a root that does not exist, a port that
/// cannot be bound.
pub async fn start(config: Config) -> Result<Studio, StudioError> {
    let token = security::new_token().map_err(|e| StudioError::Server(e.to_string()))?;
    let scene =
        volmorph_scene::setup::start_with(&config.files, &config.setups, &volmorph_io::NoProgress)
            .map_err(|e| StudioError::Start(e.to_string()))?;
    let mut roots = Roots::new(&config.roots).map_err(|e| StudioError::Server(e.to_string()))?;
    let upload_dir = std::env::temp_dir().join(format!("volmorph-studio-{}", &token[..12]));
    std::fs::create_dir_all(&upload_dir)
        .map_err(|e| StudioError::File(upload_dir.display().to_string(), e.to_string()))?;
    roots.push(
        std::fs::canonicalize(&upload_dir)
            .map_err(|e| StudioError::File(upload_dir.display().to_string(), e.to_string()))?,
    );
    let listener = tokio::net::TcpListener::bind((Ipv4Addr::LOCALHOST, config.port))
        .await
        .map_err(|e| {
            StudioError::Server(format!("cannot listen on 127.0.0.1:{}: {e}", config.port))
        })?;
    let addr = listener
        .local_addr()
        .map_err(|e| StudioError::Server(e.to_string()))?;
    let scene = Arc::new(RwLock::new(scene));
    let queue = Arc::new(Queue::new());
    let (out, _) = broadcast::channel(256);
    let running = Arc::new(Running::new(out.clone()));
    let shared = Arc::new(Shared {
        port: addr.port(),
        scene: Arc::clone(&scene),
        queue: Arc::clone(&queue),
        out: out.clone(),
        caches: Caches::default(),
        running: Arc::clone(&running),
        roots,
        upload_dir,
        next_page: AtomicU64::new(1),
    });
    let editor = Editor::new(scene, queue, out, Arc::clone(&running));
    let ticker = tokio::spawn(async move {
        let mut every = tokio::time::interval(crate::jobs::PROGRESS_INTERVAL);
        every.set_missed_tick_behavior(tokio::time::MissedTickBehavior::Delay);
        loop {
            every.tick().await;
            running.tick();
        }
    });
    std::thread::Builder::new()
        .name("volmorph-studio-editor".into())
        .spawn(move || editor.run())
        .map_err(|e| StudioError::Server(e.to_string()))?;
    let t = &token;
    let app = Router::new()
        .route(&format!("/{t}/"), get(page))
        .route(&format!("/{t}/app/{{file}}"), get(asset))
        .route(&format!("/{t}/ws"), get(ws_upgrade))
        .route(&format!("/{t}/download/{{id}}/{{file}}"), get(download))
        .route(
            &format!("/{t}/upload/{{file}}"),
            post(upload).layer(DefaultBodyLimit::max(config.upload_limit)),
        )
        .fallback(forbidden)
        .layer(middleware::from_fn_with_state(Arc::clone(&shared), guard))
        .with_state(Arc::clone(&shared));
    let server = tokio::spawn(async move {
        let _ = axum::serve(listener, app).await;
    });
    Ok(Studio {
        addr,
        token,
        shared,
        server,
        ticker,
    })
}

/// Host and Origin checks on every request (see [`security`]).
async fn guard(State(s): State<Arc<Shared>>, req: Request, next: Next) -> Response {
    let headers = req.headers();
    let host_ok = headers
        .get(header::HOST)
        .and_then(|h| h.to_str().ok())
        .is_some_and(|h| security::host_allowed(h, s.port));
    if !host_ok {
        return (StatusCode::FORBIDDEN, "wrong Host").into_response();
    }
    if let Some(o) = headers.get(header::ORIGIN)
        && !o
            .to_str()
            .is_ok_and(|o| security::origin_allowed(o, s.port))
    {
        return (StatusCode::FORBIDDEN, "wrong Origin").into_response();
    }
    next.run(req).await
}

async fn forbidden() -> Response {
    (StatusCode::FORBIDDEN, "missing or wrong launch token").into_response()
}

async fn page() -> Response {
    asset_response("index.html")
}

async fn asset(Path(file): Path<String>) -> Response {
    asset_response(&file)
}

fn asset_response(file: &str) -> Response {
    match assets::get(file) {
        Some((mime, body)) => (
            [
                (header::CONTENT_TYPE, mime),
                (header::CACHE_CONTROL, "no-store"),
                (
                    header::CONTENT_SECURITY_POLICY,
                    "default-src 'self'; connect-src 'self'; img-src 'self' blob: data:; style-src 'self'",
                ),
            ],
            body,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "no such file").into_response(),
    }
}

/// The optional query of a download: the page and request number the export reports
/// [`Kind::Progress`] to and is cancelled by ([`Kind::Cancel`]), as a WebSocket job is.
#[derive(Debug, Default, serde::Deserialize)]
struct DownloadQuery {
    page: Option<u64>,
    request: Option<u32>,
}

/// Cancels a job when dropped: the download's response future is dropped when the page
/// aborts the request, and the export stops.
struct CancelOnDrop(Arc<JobProgress>);

impl Drop for CancelOnDrop {
    fn drop(&mut self) {
        self.0.cancel();
    }
}

async fn download(
    State(s): State<Arc<Shared>>,
    Path((id, file)): Path<(u64, String)>,
    Query(q): Query<DownloadQuery>,
) -> Response {
    let shared = Arc::clone(&s);
    let job = match (q.page, q.request) {
        (Some(page), Some(request)) => Some(s.running.begin(Origin { page, request })),
        _ => None,
    };
    let progress = job.as_ref().map_or_else(
        || {
            Arc::new(JobProgress::new(Origin {
                page: 0,
                request: 0,
            }))
        },
        |j| Arc::clone(j.progress()),
    );
    let _cancel_on_drop = CancelOnDrop(Arc::clone(&progress));
    let res = tokio::task::spawn_blocking(move || -> Result<Vec<u8>, String> {
        let _job = job;
        if file.contains('/') || file.contains('\\') || file.starts_with('.') {
            return Err(format!("file name {file:?} must be plain"));
        }
        let dir = shared.upload_dir.join(format!(
            "export-{}",
            shared.next_page.fetch_add(1, Ordering::Relaxed)
        ));
        std::fs::create_dir_all(&dir).map_err(|e| e.to_string())?;
        let path = dir.join(&file);
        let scene = shared.scene.read().unwrap_or_else(|p| p.into_inner());
        let r = scene
            .export_with(ObjectId(id), &path, &*progress)
            .map_err(|e| {
                if e.is_cancelled() {
                    "cancelled".to_owned()
                } else {
                    e.to_string()
                }
            })
            .and_then(|()| std::fs::read(&path).map_err(|e| e.to_string()));
        let _ = std::fs::remove_dir_all(&dir);
        r
    })
    .await;
    match res {
        Ok(Ok(bytes)) => (
            [(header::CONTENT_TYPE, "application/octet-stream")],
            Body::from(bytes),
        )
            .into_response(),
        Ok(Err(e)) => (StatusCode::BAD_REQUEST, e).into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

async fn upload(State(s): State<Arc<Shared>>, Path(file): Path<String>, body: Bytes) -> Response {
    if file.contains('/') || file.contains('\\') || file.starts_with('.') || file.is_empty() {
        return (
            StatusCode::BAD_REQUEST,
            format!("file name {file:?} must be plain"),
        )
            .into_response();
    }
    let root = s.roots.list().len() - 1;
    let path = match s.roots.resolve_new(root, &file) {
        Ok(p) => p,
        Err(e) => return (StatusCode::BAD_REQUEST, e.to_string()).into_response(),
    };
    match volmorph_io::write_atomic::<volmorph_io::IoError, _>(&path, |w| {
        std::io::Write::write_all(w, &body).map_err(|e| volmorph_io::IoError::os(&path, e))
    }) {
        Ok(()) => (
            [(header::CONTENT_TYPE, "application/json")],
            json!({"root": root, "path": file, "bytes": body.len()}).to_string(),
        )
            .into_response(),
        Err(e) => (StatusCode::INTERNAL_SERVER_ERROR, e.to_string()).into_response(),
    }
}

async fn ws_upgrade(
    State(s): State<Arc<Shared>>,
    headers: HeaderMap,
    ws: WebSocketUpgrade,
) -> Response {
    // The guard refused a foreign Origin; the WebSocket also requires one.
    if headers.get(header::ORIGIN).is_none() {
        return (
            StatusCode::FORBIDDEN,
            "the WebSocket needs an Origin header",
        )
            .into_response();
    }
    ws.max_message_size(MAX_CLIENT_FRAME)
        .max_frame_size(MAX_CLIENT_FRAME)
        .on_upgrade(move |socket| page_socket(s, socket))
}

async fn page_socket(s: Arc<Shared>, mut socket: WebSocket) {
    let page = s.next_page.fetch_add(1, Ordering::Relaxed);
    let mut pushes = s.out.subscribe();
    let (reply_tx, mut reply_rx) = mpsc::unbounded_channel::<Vec<u8>>();
    loop {
        tokio::select! {
            msg = socket.recv() => {
                let Some(Ok(msg)) = msg else { break };
                match msg {
                    Message::Binary(bytes) => match Frame::decode(&bytes) {
                        Ok(frame) => handle(&s, page, frame, &reply_tx),
                        Err(e) => {
                            let fatal = matches!(e, FrameError::Version { .. } | FrameError::Magic);
                            let f = Frame::new(Kind::Error, 0, json!({"message": e.to_string(), "fatal": fatal, "version": VERSION}));
                            if socket.send(Message::Binary(f.encode().into())).await.is_err() || fatal {
                                break;
                            }
                        }
                    },
                    Message::Text(_) => {
                        let f = Frame::new(Kind::Error, 0, json!({"message": "the studio protocol uses binary frames only"}));
                        if socket.send(Message::Binary(f.encode().into())).await.is_err() { break; }
                    }
                    Message::Close(_) => break,
                    _ => {}
                }
            }
            reply = reply_rx.recv() => {
                let Some(bytes) = reply else { break };
                if socket.send(Message::Binary(bytes.into())).await.is_err() { break; }
            }
            push = pushes.recv() => {
                match push {
                    Ok(o) => {
                        if o.page.is_none_or(|p| p == page)
                            && socket.send(Message::Binary(o.bytes.as_ref().clone().into())).await.is_err() {
                            break;
                        }
                    }
                    Err(broadcast::error::RecvError::Lagged(_)) => {
                        // Missed pushes: send the whole object list so the page resyncs.
                        let f = views::scene_frame(&s.scene.read().unwrap_or_else(|p| p.into_inner()), 0);
                        if socket.send(Message::Binary(f.encode().into())).await.is_err() { break; }
                    }
                    Err(broadcast::error::RecvError::Closed) => break,
                }
            }
        }
    }
}

/// A gesture number unique across pages.
fn gesture_key(page: u64, h: &Value) -> Result<u64, QueryError> {
    Ok((page << 32) | (u64_field(h, "gesture")? & 0xffff_ffff))
}

fn handle(s: &Arc<Shared>, page: u64, frame: Frame, reply: &mpsc::UnboundedSender<Vec<u8>>) {
    let origin = Origin {
        page,
        request: frame.request,
    };
    if frame.kind == Kind::Cancel {
        match u64_field(&frame.header, "request").map(|r| u32::try_from(r).unwrap_or(0)) {
            Ok(request) => cancel(s, Origin { page, request }),
            Err(e) => {
                let _ = reply
                    .send(Frame::new(Kind::Error, frame.request, json!({"message": e.0})).encode());
            }
        }
        return;
    }
    match edit_of(s, page, &frame) {
        Ok(Some(work)) => {
            s.queue.push(Job { origin, work });
            return;
        }
        Ok(None) => {}
        Err(e) => {
            let _ = reply
                .send(Frame::new(Kind::Error, frame.request, json!({"message": e.0})).encode());
            return;
        }
    }
    // Queries and file operations: off the socket's task, under a read lock.
    let s = Arc::clone(s);
    let reply = reply.clone();
    tokio::task::spawn_blocking(move || {
        let r = query(&s, page, &frame);
        let f =
            r.unwrap_or_else(|e| Frame::new(Kind::Error, frame.request, json!({"message": e.0})));
        let _ = reply.send(f.encode());
    });
}

/// Stop the job of `origin`: the running one is told to stop (it answers itself); a queued
/// one is taken out of the queue and answered here. Nothing for a job that has ended.
fn cancel(s: &Shared, origin: Origin) {
    if s.running.cancel(origin) {
        return;
    }
    if s.queue.remove(|j| j.origin == origin).is_some() {
        let e = volmorph_scene::SceneError::Cancelled(volmorph_io::Cancelled);
        let _ = s.out.send(Outgoing {
            page: Some(origin.page),
            bytes: Arc::new(crate::jobs::error_frame(origin.request, &e).encode()),
        });
    }
}

/// The edit a frame asks for (`None` for queries).
fn edit_of(s: &Shared, page: u64, frame: &Frame) -> Result<Option<Work>, QueryError> {
    let h = &frame.header;
    Ok(Some(match frame.kind {
        Kind::Drag => Work::Drag {
            gesture: gesture_key(page, h)?,
            map: ObjectId(u64_field(h, "map")?),
            start: vec3_field(h, "start")?,
            target: vec3_field(h, "target")?,
            radius: views::f64_field(h, "radius")?,
        },
        Kind::MoveControlPoints => {
            let pts = h.get("points").and_then(Value::as_array).ok_or_else(|| {
                QueryError("field \"points\" must be a list of [index, x, y, z]".into())
            })?;
            let mut changes = std::collections::BTreeMap::new();
            for p in pts {
                let a: Vec<f64> = p
                    .as_array()
                    .map(|a| a.iter().filter_map(Value::as_f64).collect())
                    .unwrap_or_default();
                if a.len() != 4 || a[0] < 0.0 || a[0].fract() != 0.0 {
                    return Err(QueryError("each point must be [index, x, y, z]".into()));
                }
                changes.insert(a[0] as usize, glam::DVec3::new(a[1], a[2], a[3]));
            }
            Work::Parameters {
                gesture: gesture_key(page, h)?,
                map: ObjectId(u64_field(h, "map")?),
                changes,
            }
        }
        Kind::EndGesture => Work::EndGesture {
            gesture: gesture_key(page, h)?,
        },
        Kind::Undo => Work::Undo,
        Kind::Redo => Work::Redo,
        Kind::Setup => Work::Setup(
            serde_json::from_value::<Setup>(h.clone())
                .map_err(|e| QueryError(format!("bad set-up: {e}")))?,
        ),
        Kind::Command => {
            let gesture = h.get("gesture").map(|_| gesture_key(page, h)).transpose()?;
            if let Some(r) = command_json::sculpt(h)? {
                Work::Sculpt(r, gesture)
            } else if let Some(r) = crate::lobes::parse(h)? {
                Work::Lobes(r)
            } else {
                Work::Command(Box::new(command_json::parse(h)?), gesture)
            }
        }
        Kind::OpenFile => Work::Open(resolve(s, h)?),
        Kind::SaveScene => Work::Save(resolve_new(s, h)?),
        Kind::LoadScene => Work::Load(resolve(s, h)?),
        Kind::Export => Work::Export(ObjectId(u64_field(h, "id")?), resolve_new(s, h)?),
        _ => return Ok(None),
    }))
}

fn resolve_path(s: &Shared, h: &Value, new: bool) -> Result<PathBuf, QueryError> {
    let root = usize::try_from(u64_field(h, "root")?).unwrap_or(usize::MAX);
    let path = h
        .get("path")
        .and_then(Value::as_str)
        .ok_or_else(|| QueryError("field \"path\" must be a string".into()))?;
    let r = if new {
        s.roots.resolve_new(root, path)
    } else {
        s.roots.resolve(root, path)
    };
    r.map_err(|e| QueryError(e.to_string()))
}

fn resolve(s: &Shared, h: &Value) -> Result<PathBuf, QueryError> {
    resolve_path(s, h, false)
}

fn resolve_new(s: &Shared, h: &Value) -> Result<PathBuf, QueryError> {
    resolve_path(s, h, true)
}

fn query(s: &Shared, page: u64, frame: &Frame) -> Result<Frame, QueryError> {
    let h = &frame.header;
    let r = frame.request;
    let scene = s.scene.read().unwrap_or_else(|p| p.into_inner());
    match frame.kind {
        Kind::Hello => Ok(Frame::new(
            Kind::Welcome,
            r,
            json!({
                "version": VERSION,
                "page": page,
                "colormaps": views::colormaps_json(),
                "roots": s.roots.list().iter().map(|p| p.display().to_string()).collect::<Vec<_>>(),
                "scene": views::scene_frame(&scene, r).header,
            }),
        )),
        Kind::ListObjects => Ok(views::scene_frame(&scene, r)),
        Kind::GetSlice => s.caches.slice(&scene, h, r),
        Kind::GetJacobian => views::jacobian_frame(&scene, h, r),
        Kind::GetVolume => views::volume_frame(&scene, h, r),
        Kind::GetProxy => s.caches.proxy(&scene, h, r),
        Kind::GetMesh => views::mesh_frame(&scene, h, r),
        Kind::GetLattice => views::overlay_frame(&scene, h, r),
        Kind::Probe => views::probe_frame(&scene, h, r),
        Kind::GetTransfer => views::transfer_frame(h, r),
        Kind::ListDir => {
            let dir = resolve(s, h)?;
            let mut entries = Vec::new();
            for e in std::fs::read_dir(&dir)
                .map_err(|e| QueryError(e.to_string()))?
                .flatten()
            {
                let meta = e.metadata().ok();
                entries.push(json!({
                    "name": e.file_name().to_string_lossy(),
                    "dir": meta.as_ref().is_some_and(std::fs::Metadata::is_dir),
                    "size": meta.as_ref().map_or(0, std::fs::Metadata::len),
                }));
            }
            entries.sort_by(|a, b| a["name"].as_str().cmp(&b["name"].as_str()));
            Ok(Frame::new(
                Kind::Listing,
                r,
                json!({"root": h["root"], "path": h["path"], "entries": entries}),
            ))
        }
        k => Err(QueryError(format!(
            "message kind {k:?} is not a request a page sends"
        ))),
    }
}
