//! The studio's protocol and security rules, tested as a client against the running server:
//! every message kind, the version check, errors, coalescing, the token, Host and Origin
//! checks, bounded messages and bodies, and file confinement.

use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio_tungstenite::tungstenite::{Message, client::IntoClientRequest, http::HeaderValue};
use volmorph_scene::setup::Setup;
use volmorph_studio::protocol::{Frame, Kind, read_f32};
use volmorph_studio::{Config, Studio, start};
use volmorph_volume::AnyVolume;
use volmorph_volume::phantom::{self, Phantom};
use volmorph_volume::slice::{self, Axis, SlicePosition};

type Ws =
    tokio_tungstenite::WebSocketStream<tokio_tungstenite::MaybeTlsStream<tokio::net::TcpStream>>;

const SIZE: usize = 40;

async fn studio(root: &std::path::Path, upload_limit: usize) -> Studio {
    start(Config {
        files: vec![],
        roots: vec![root.to_path_buf()],
        port: 0,
        upload_limit,
        setups: vec![
            Setup::Phantom {
                model: "teapot".into(),
                size: SIZE,
            },
            Setup::DirectManipulation {
                volume: 1,
                counts: 7,
                level: 127.0,
            },
        ],
    })
    .await
    .unwrap()
}

async fn connect_with(s: &Studio, path: &str, origin: Option<&str>) -> Result<Ws, String> {
    let url = format!("ws://{}/{}", s.addr(), path);
    let mut req = url.into_client_request().unwrap();
    if let Some(o) = origin {
        req.headers_mut()
            .insert("Origin", HeaderValue::from_str(o).unwrap());
    }
    tokio_tungstenite::connect_async(req)
        .await
        .map(|(ws, _)| ws)
        .map_err(|e| e.to_string())
}

async fn connect(s: &Studio) -> Ws {
    let origin = format!("http://{}", s.addr());
    let mut ws = connect_with(s, &format!("{}/ws", s.token()), Some(&origin))
        .await
        .unwrap();
    send(&mut ws, Kind::Hello, 1, json!({})).await;
    let w = recv_kind(&mut ws, Kind::Welcome).await;
    assert_eq!(w.header["version"], 1);
    ws
}

async fn send(ws: &mut Ws, kind: Kind, request: u32, header: Value) {
    ws.send(Message::Binary(
        Frame::new(kind, request, header).encode().into(),
    ))
    .await
    .unwrap();
}

async fn recv(ws: &mut Ws) -> Option<Frame> {
    loop {
        let m = tokio::time::timeout(Duration::from_secs(60), ws.next())
            .await
            .ok()??;
        match m.ok()? {
            Message::Binary(b) => return Some(Frame::decode(&b).unwrap()),
            Message::Close(_) => return None,
            _ => {}
        }
    }
}

async fn recv_kind(ws: &mut Ws, kind: Kind) -> Frame {
    loop {
        let f = recv(ws).await.expect("connection closed");
        if f.kind == kind {
            return f;
        }
        assert_ne!(f.kind, Kind::Error, "unexpected error {:?}", f.header);
    }
}

/// A reply to `request` (skipping pushes).
async fn reply(ws: &mut Ws, request: u32) -> Frame {
    loop {
        let f = recv(ws).await.expect("connection closed");
        if f.request == request && f.kind != Kind::Changed {
            return f;
        }
    }
}

async fn ask(ws: &mut Ws, kind: Kind, request: u32, header: Value) -> Frame {
    send(ws, kind, request, header).await;
    reply(ws, request).await
}

/// Status code of a raw HTTP request.
async fn http(s: &Studio, request: &str) -> u16 {
    let mut c = tokio::net::TcpStream::connect(s.addr()).await.unwrap();
    c.write_all(request.as_bytes()).await.unwrap();
    let mut buf = [0u8; 64];
    let mut n = 0;
    while n < 12 {
        let k = c.read(&mut buf[n..]).await.unwrap();
        if k == 0 {
            break;
        }
        n += k;
    }
    String::from_utf8_lossy(&buf[9..12]).parse().unwrap()
}

fn get(s: &Studio, path: &str, extra: &str) -> String {
    format!(
        "GET {path} HTTP/1.1\r\nHost: {}\r\n{extra}Connection: close\r\n\r\n",
        s.addr()
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn token_is_required_on_every_http_request_and_the_websocket() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let t = s.token().to_owned();
    assert_eq!(http(&s, &get(&s, &format!("/{t}/"), "")).await, 200);
    assert_eq!(
        http(&s, &get(&s, &format!("/{t}/app/main.js"), "")).await,
        200
    );
    assert_eq!(http(&s, &get(&s, "/", "")).await, 403);
    assert_eq!(http(&s, &get(&s, "/app/main.js", "")).await, 403);
    // The token with its last digit changed (a fixed last digit equals the token 1 in 16).
    let last = if t.ends_with('0') { '1' } else { '0' };
    let wrong = format!("{}{last}", &t[..31]);
    assert_eq!(http(&s, &get(&s, &format!("/{wrong}/"), "")).await, 403);
    let origin = format!("http://{}", s.addr());
    assert!(
        connect_with(&s, &format!("{wrong}/ws"), Some(&origin))
            .await
            .is_err()
    );
    assert!(connect_with(&s, "ws", Some(&origin)).await.is_err());
    assert!(
        connect_with(&s, &format!("{t}/ws"), Some(&origin))
            .await
            .is_ok()
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn host_and_origin_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let t = s.token().to_owned();
    // DNS rebinding: another name for 127.0.0.1.
    let rebound = format!(
        "GET /{t}/ HTTP/1.1\r\nHost: evil.example:{}\r\nConnection: close\r\n\r\n",
        s.addr().port()
    );
    assert_eq!(http(&s, &rebound).await, 403);
    assert_eq!(
        http(
            &s,
            &get(&s, &format!("/{t}/"), "Origin: http://evil.example\r\n")
        )
        .await,
        403
    );
    let own = format!("Origin: http://{}\r\n", s.addr());
    assert_eq!(http(&s, &get(&s, &format!("/{t}/"), &own)).await, 200);
    assert!(
        connect_with(&s, &format!("{t}/ws"), Some("http://evil.example"))
            .await
            .is_err()
    );
    assert!(
        connect_with(&s, &format!("{t}/ws"), None).await.is_err(),
        "the WebSocket needs an Origin"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn other_versions_and_malformed_frames_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    // Malformed but current version: an error, the socket stays open.
    ws.send(Message::Binary(b"VMST\x01\x00".to_vec().into()))
        .await
        .unwrap();
    let e = recv_kind(&mut ws, Kind::Error).await;
    assert!(e.header["message"].as_str().unwrap().contains("truncated"));
    ws.send(Message::Text("hello".into())).await.unwrap();
    let e = recv_kind(&mut ws, Kind::Error).await;
    assert!(e.header["message"].as_str().unwrap().contains("binary"));
    let f = ask(&mut ws, Kind::ListObjects, 5, json!({})).await;
    assert_eq!(f.kind, Kind::Scene);
    // Another version: told so, then closed.
    let mut b = Frame::new(Kind::ListObjects, 6, json!({})).encode();
    b[4] = 9;
    ws.send(Message::Binary(b.into())).await.unwrap();
    let e = recv_kind(&mut ws, Kind::Error).await;
    assert_eq!(e.header["fatal"], true);
    assert!(e.header["message"].as_str().unwrap().contains("version 9"));
    assert!(
        recv(&mut ws).await.is_none(),
        "the socket is closed after a version mismatch"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn messages_and_bodies_are_bounded() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1000).await;
    let mut ws = connect(&s).await;
    let big = vec![0u8; (1 << 20) + 100];
    let _ = ws.send(Message::Binary(big.into())).await;
    assert!(
        recv(&mut ws).await.is_none(),
        "an oversized message closes the socket"
    );
    let t = s.token();
    let origin = format!("Origin: http://{}\r\n", s.addr());
    let post = |n: usize| {
        format!(
            "POST /{t}/upload/a.obj HTTP/1.1\r\nHost: {}\r\n{origin}Content-Length: {n}\r\nConnection: close\r\n\r\n{}",
            s.addr(),
            "x".repeat(n)
        )
    };
    assert_eq!(http(&s, &post(2000)).await, 413);
    assert_eq!(http(&s, &post(500)).await, 200);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn file_access_is_confined_to_the_roots() {
    let dir = tempfile::tempdir().unwrap();
    let outside = tempfile::tempdir().unwrap();
    let vol = phantom::density(Phantom::Sphere, [12; 3]).unwrap();
    volmorph_volume_io::write(
        &outside.path().join("secret.nii"),
        &AnyVolume::from(vol.clone()),
    )
    .unwrap();
    volmorph_volume_io::write(&dir.path().join("ball.nii"), &AnyVolume::from(vol)).unwrap();
    #[cfg(unix)]
    std::os::unix::fs::symlink(outside.path(), dir.path().join("link")).unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    let l = ask(&mut ws, Kind::ListDir, 2, json!({"root": 0, "path": "."})).await;
    assert_eq!(l.kind, Kind::Listing);
    let names: Vec<&str> = l.header["entries"]
        .as_array()
        .unwrap()
        .iter()
        .map(|e| e["name"].as_str().unwrap())
        .collect();
    assert!(names.contains(&"ball.nii"));
    for (path, why) in [
        ("..", "'..'"),
        ("/etc", "'..'"),
        ("link", "outside"),
        ("link/secret.nii", "outside"),
    ] {
        let e = ask(&mut ws, Kind::ListDir, 3, json!({"root": 0, "path": path})).await;
        assert_eq!(e.kind, Kind::Error, "{path}");
        assert!(
            e.header["message"].as_str().unwrap().contains(why),
            "{path}: {}",
            e.header
        );
        send(&mut ws, Kind::OpenFile, 4, json!({"root": 0, "path": path})).await;
        assert_eq!(reply(&mut ws, 4).await.kind, Kind::Error, "{path}");
    }
    let e = ask(
        &mut ws,
        Kind::SaveScene,
        5,
        json!({"root": 0, "path": "link/x.vmproj"}),
    )
    .await;
    assert_eq!(e.kind, Kind::Error);
    // Inside the root: open, save, export.
    send(
        &mut ws,
        Kind::OpenFile,
        6,
        json!({"root": 0, "path": "ball.nii"}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    assert_eq!(c.header["request"], 6);
    assert_eq!(c.header["added"].as_array().unwrap().len(), 1);
    let d = ask(
        &mut ws,
        Kind::SaveScene,
        7,
        json!({"root": 0, "path": "s.vmproj"}),
    )
    .await;
    assert_eq!(d.kind, Kind::Done, "{}", d.header);
    assert!(dir.path().join("s.vmproj").exists());
    let d = ask(
        &mut ws,
        Kind::Export,
        8,
        json!({"root": 0, "path": "warped.nii.gz", "id": 3}),
    )
    .await;
    assert_eq!(d.kind, Kind::Done, "{}", d.header);
    let d = ask(
        &mut ws,
        Kind::LoadScene,
        9,
        json!({"root": 0, "path": "s.vmproj"}),
    )
    .await;
    assert_eq!(d.kind, Kind::Done, "{}", d.header);
}

/// Burst of drags while edits compute: fewer edits run than drags sent, the lattice ends
/// where the last drag put the grabbed point, and the whole gesture undoes as one step.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_burst_of_drags_is_coalesced_and_ends_at_the_last_target() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    let start = [0.6, 0.0, 0.04];
    let n = 60;
    let target = |k: usize| [0.6 + 0.003 * k as f64, 0.0, 0.04 - 0.004 * k as f64];
    for k in 1..=n {
        send(
            &mut ws,
            Kind::Drag,
            100 + k as u32,
            json!({"gesture": 1, "map": 2, "start": start, "target": target(k), "radius": 0.5}),
        )
        .await;
    }
    send(&mut ws, Kind::EndGesture, 999, json!({"gesture": 1})).await;
    let mut drags = 0;
    let mut last_request = 0;
    loop {
        let c = recv_kind(&mut ws, Kind::Changed).await;
        match c.header["edit"].as_str().unwrap() {
            "drag" => {
                drags += 1;
                last_request = c.header["request"].as_u64().unwrap();
                assert!(c.header["dirty"].as_array().is_some_and(|d| !d.is_empty()));
            }
            "end-gesture" => break,
            e => panic!("unexpected edit {e}"),
        }
    }
    assert!(drags >= 1 && drags < n, "{drags} edits ran for {n} drags");
    assert_eq!(
        last_request,
        100 + n as u64,
        "the last edit is the newest drag"
    );
    let p = ask(&mut ws, Kind::Probe, 2, json!({"map": 2, "point": start})).await;
    let img: Vec<f64> = serde_json::from_value(p.header["image"].clone()).unwrap();
    for c in 0..3 {
        assert!(
            (img[c] - target(n)[c]).abs() < 1e-6,
            "{img:?} vs {:?}",
            target(n)
        );
    }
    send(&mut ws, Kind::Undo, 3, json!({})).await;
    let u = recv_kind(&mut ws, Kind::Changed).await;
    assert_eq!(u.header["edit"], "undo");
    let p = ask(&mut ws, Kind::Probe, 4, json!({"map": 2, "point": start})).await;
    let img: Vec<f64> = serde_json::from_value(p.header["image"].clone()).unwrap();
    for c in 0..3 {
        assert!(
            (img[c] - start[c]).abs() < 1e-9,
            "one undo takes the whole gesture back: {img:?}"
        );
    }
    send(&mut ws, Kind::Redo, 5, json!({})).await;
    assert_eq!(
        recv_kind(&mut ws, Kind::Changed).await.header["edit"],
        "redo"
    );
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn every_query_kind_answers() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    let sc = ask(&mut ws, Kind::ListObjects, 2, json!({})).await;
    let kinds: Vec<&str> = sc.header["objects"]
        .as_array()
        .unwrap()
        .iter()
        .map(|o| o["kind"].as_str().unwrap())
        .collect();
    assert_eq!(kinds, ["volume", "map", "derived", "derived"]);
    // The slice is the library's slice.
    let f = ask(
        &mut ws,
        Kind::GetSlice,
        3,
        json!({"volume": 1, "axis": 1, "index": 17}),
    )
    .await;
    assert_eq!(f.kind, Kind::Slice);
    let vol = AnyVolume::from(phantom::density(Phantom::Teapot, [SIZE; 3]).unwrap());
    let expect = slice::extract(&vol, Axis::Y, SlicePosition::Index(17.0)).unwrap();
    assert_eq!(read_f32(&f.payload), expect.values);
    assert_eq!(f.header["width"], expect.width);
    let w: Vec<f64> = serde_json::from_value(f.header["window"].clone()).unwrap();
    assert!(w[0] < w[1]);
    let e = ask(&mut ws, Kind::GetSlice, 4, json!({"volume": 1, "axis": 3})).await;
    assert_eq!(e.kind, Kind::Error);
    let e = ask(&mut ws, Kind::GetSlice, 4, json!({"volume": 77, "axis": 0})).await;
    assert!(e.header["message"].as_str().unwrap().contains("#77"));
    // Volume texture.
    let v = ask(&mut ws, Kind::GetVolume, 5, json!({"volume": 1})).await;
    assert_eq!(v.payload.len(), SIZE * SIZE * SIZE);
    assert_eq!(
        v.payload,
        *vol.as_bytes(),
        "a u8 volume spanning 0..255 is sent as it is"
    );
    // Proxy geometry: indices within the vertices, texture coordinates in [0, 1].
    let p = ask(
        &mut ws,
        Kind::GetProxy,
        6,
        json!({"volume": 1, "forward": [0.3, -0.5, -0.8], "slices": 64}),
    )
    .await;
    assert_eq!(p.kind, Kind::Proxy, "{}", p.header);
    let nv = p.header["vertices"].as_u64().unwrap() as usize;
    let ni = p.header["indices"].as_u64().unwrap() as usize;
    assert!(nv > 64 * 3 && ni.is_multiple_of(3));
    let verts = read_f32(&p.payload[..nv * 24]);
    assert!(
        verts
            .chunks(6)
            .all(|v| v[3..].iter().all(|t| (-1e-4..=1.0001).contains(t)))
    );
    let idx: Vec<u32> = p.payload[nv * 24..]
        .chunks(4)
        .map(|c| u32::from_le_bytes([c[0], c[1], c[2], c[3]]))
        .collect();
    assert_eq!(idx.len(), ni);
    assert!(idx.iter().all(|&i| (i as usize) < nv));
    let e = ask(
        &mut ws,
        Kind::GetProxy,
        6,
        json!({"volume": 1, "forward": [0, 0, 0], "slices": 64}),
    )
    .await;
    assert_eq!(e.kind, Kind::Error);
    // Mesh (the isosurface) and the lattice.
    let m = ask(&mut ws, Kind::GetMesh, 7, json!({"id": 4})).await;
    let (nv, nt) = (
        m.header["vertices"].as_u64().unwrap() as usize,
        m.header["triangles"].as_u64().unwrap() as usize,
    );
    assert!(nt > 100);
    assert_eq!(m.payload.len(), nv * 24 + nt * 12);
    let l = ask(&mut ws, Kind::GetLattice, 8, json!({"map": 2})).await;
    assert_eq!(l.header["counts"], json!([7, 7, 7]));
    assert_eq!(l.payload.len(), 7 * 7 * 7 * 12);
    let e = ask(&mut ws, Kind::GetLattice, 8, json!({"map": 1})).await;
    assert_eq!(e.kind, Kind::Error);
    // Transfer table; a malformed one is an error naming the entry.
    let t = ask(
        &mut ws,
        Kind::GetTransfer,
        9,
        json!({"text": "0:0,0,0,0; 255:1,1,1,1", "min": 0, "max": 255}),
    )
    .await;
    assert_eq!(t.payload.len(), 1024);
    assert_eq!(&t.payload[1020..], &[255, 255, 255, 255]);
    let e = ask(
        &mut ws,
        Kind::GetTransfer,
        9,
        json!({"text": "0:zero", "min": 0, "max": 1}),
    )
    .await;
    assert!(e.header["message"].as_str().unwrap().contains("0:zero"));
    // Lattice control points moved directly; an F-rep syntax error at its line.
    send(
        &mut ws,
        Kind::MoveControlPoints,
        10,
        json!({"gesture": 4, "map": 2, "points": [[171, 0.1, 0.1, 0.1]]}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    assert_eq!(c.header["edit"], "parameters");
    let l = ask(&mut ws, Kind::GetLattice, 11, json!({"map": 2})).await;
    assert_eq!(
        &read_f32(&l.payload)[171 * 3..171 * 3 + 3],
        &[0.1f32, 0.1, 0.1]
    );
    send(&mut ws, Kind::Command, 12, json!({"command": "add-frep", "name": "m", "source": "m(x[3], a[1]) {\n  m = 1 - x[1] *;\n}"})).await;
    let e = reply(&mut ws, 12).await;
    assert_eq!(e.kind, Kind::Error);
    assert_eq!(e.header["line"], 2, "{}", e.header);
    send(&mut ws, Kind::Command, 13, json!({"command": "nonsense"})).await;
    assert_eq!(reply(&mut ws, 13).await.kind, Kind::Error);
    // Set-up of handles, then a handle move through a command.
    send(
        &mut ws,
        Kind::Setup,
        14,
        json!({"setup": "handles", "volume": 1, "method": "affine"}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    assert_eq!(c.header["added"].as_array().unwrap().len(), 2);
    let hm = c.header["added"][0].as_u64().unwrap();
    send(&mut ws, Kind::Command, 15, json!({"command": "move-handle", "map": hm, "index": 8, "source": [0, 0, 0], "target": [0.1, 0, 0]})).await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    assert!(
        c.header["modified"].as_array().unwrap().len() >= 2,
        "{}",
        c.header
    );
}

/// Regression (a slice drag sent no edit and the 3D view drew no lattice): the page looks the
/// lattice up by the Scene's `map.kind`, which is the map JSON's kind; the page's constant
/// must be that kind.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_page_finds_the_lattice_under_the_scene_map_kind() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    let sc = ask(&mut ws, Kind::ListObjects, 2, json!({})).await;
    let lattice = sc.header["objects"]
        .as_array()
        .unwrap()
        .iter()
        .find(|o| o["kind"] == "map")
        .expect("the set-up adds a lattice map");
    let kind = lattice["map"]["kind"].as_str().unwrap();
    assert_eq!(kind, volmorph_lattice::json::LATTICE_JSON_KIND);
    assert_eq!(lattice["map"]["counts"], json!([7, 7, 7]));
    let page = std::str::from_utf8(volmorph_studio::assets::get("main.js").unwrap().1).unwrap();
    assert!(
        page.contains(&format!("export const LATTICE_KIND = '{kind}';")),
        "main.js must look lattices up as {kind:?}"
    );
}

/// The Jacobian slice of a deformed lattice equals the scene's Jacobian volume (computed on
/// the whole grid) on that plane, its `folded` counts `J ≤ 0`, and a probe of a point list maps
/// each point as a one-point probe does.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn jacobian_slices_and_point_lists_agree_with_the_scene() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    send(
        &mut ws,
        Kind::Drag,
        2,
        json!({"gesture": 1, "map": 2, "start": [0.6, 0.0, 0.04], "target": [0.75, 0.05, -0.1], "radius": 0.5}),
    )
    .await;
    send(&mut ws, Kind::EndGesture, 3, json!({"gesture": 1})).await;
    while recv_kind(&mut ws, Kind::Changed).await.header["edit"] != "end-gesture" {}
    send(
        &mut ws,
        Kind::Command,
        4,
        json!({"command": "add-derived", "name": "jac", "recipe": {"recipe": "jacobian", "map": 2, "grid": 1}}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    let jac = c.header["added"][0].as_u64().unwrap();
    for (axis, index) in [(0, 30), (1, 20), (2, 21)] {
        let whole = ask(
            &mut ws,
            Kind::GetSlice,
            5,
            json!({"volume": jac, "axis": axis, "index": index}),
        )
        .await;
        let plane = ask(
            &mut ws,
            Kind::GetJacobian,
            6,
            json!({"map": 2, "volume": 1, "axis": axis, "index": index}),
        )
        .await;
        assert_eq!(plane.kind, Kind::Slice, "{}", plane.header);
        assert_eq!(plane.header["width"], whole.header["width"]);
        assert_eq!(plane.header["height"], whole.header["height"]);
        let (a, b) = (read_f32(&whole.payload), read_f32(&plane.payload));
        assert_eq!(a.len(), b.len());
        let worst = a
            .iter()
            .zip(&b)
            .map(|(x, y)| (x - y).abs() / x.abs().max(1.0))
            .fold(0.0_f32, f32::max);
        assert!(worst < 1e-5, "axis {axis}: the plane differs by {worst}");
        assert!(
            b.iter().any(|&j| (j - 1.0).abs() > 1e-3),
            "the drag changes the Jacobian on axis {axis}"
        );
        let folded = b.iter().filter(|&&j| j <= 0.0).count();
        assert_eq!(plane.header["folded"], folded);
    }
    let e = ask(
        &mut ws,
        Kind::GetJacobian,
        7,
        json!({"map": 1, "volume": 1, "axis": 0}),
    )
    .await;
    assert_eq!(e.kind, Kind::Error);
    let points = [[0.6, 0.0, 0.04], [0.0, 0.0, 0.0], [-0.5, 0.3, 0.2]];
    let list = ask(&mut ws, Kind::Probe, 8, json!({"map": 2, "points": points})).await;
    assert_eq!(list.header["count"], 3);
    let images = read_f32(&list.payload);
    for (i, p) in points.iter().enumerate() {
        let one = ask(&mut ws, Kind::Probe, 9, json!({"map": 2, "point": p})).await;
        let img: Vec<f64> = serde_json::from_value(one.header["image"].clone()).unwrap();
        for c in 0..3 {
            assert_eq!(images[3 * i + c], img[c] as f32);
        }
    }
    let e = ask(
        &mut ws,
        Kind::Probe,
        10,
        json!({"map": 2, "points": [[0.0, 0.0, 0.0], [1.0, "x", 0.0]]}),
    )
    .await;
    assert!(e.header["message"].as_str().unwrap().contains("point 1"));
}

/// A long job (a 512³ teapot sampled) sends its page Progress frames — its request, the
/// library's stage and counts, no faster than 10 a second — and a Cancel stops it: it is
/// answered by an Error `{cancelled: true}`, no Changed, and the scene (objects and both
/// histories) is as before. A queued job is cancelled before it starts. A short edit sends
/// no Progress at all.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_long_job_reports_progress_and_cancel_leaves_the_scene_unchanged() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    let before = ask(&mut ws, Kind::ListObjects, 2, json!({})).await.header;
    send(
        &mut ws,
        Kind::Setup,
        50,
        json!({"setup": "phantom", "model": "teapot", "size": 512}),
    )
    .await;
    let started = std::time::Instant::now();
    let mut progress = Vec::new();
    while progress.len() < 4 {
        let f = recv(&mut ws).await.expect("connection closed");
        assert!(
            f.kind != Kind::Changed && f.kind != Kind::Error,
            "the job ended before it was cancelled: {:?}",
            f.header
        );
        if f.kind == Kind::Progress {
            progress.push((started.elapsed(), f.header));
        }
    }
    let first = progress[0].0;
    assert!(
        first >= volmorph_studio::jobs::PROGRESS_DELAY,
        "first progress after {first:?}"
    );
    for w in progress.windows(2) {
        let gap = w[1].0 - w[0].0;
        assert!(
            gap >= std::time::Duration::from_millis(80),
            "frames {gap:?} apart"
        );
        let (a, b) = (&w[0].1, &w[1].1);
        assert!(b["done"].as_u64() >= a["done"].as_u64(), "{a} then {b}");
    }
    for (_, h) in &progress {
        assert_eq!(h["request"], 50);
        assert_eq!(h["label"], "teapot density");
        assert_eq!(h["total"], 512);
        assert!(h["done"].as_u64().unwrap() <= 512);
    }
    send(&mut ws, Kind::Cancel, 51, json!({"request": 50})).await;
    let at = std::time::Instant::now();
    loop {
        let f = recv(&mut ws).await.expect("connection closed");
        assert_ne!(f.kind, Kind::Changed, "a cancelled job changes nothing");
        if f.kind == Kind::Error {
            assert_eq!(f.request, 50);
            assert_eq!(f.header["cancelled"], true, "{}", f.header);
            assert_eq!(f.header["message"], "cancelled");
            break;
        }
    }
    assert!(
        at.elapsed() < std::time::Duration::from_secs(10),
        "the job stopped {:?} after Cancel",
        at.elapsed()
    );
    let after = ask(&mut ws, Kind::ListObjects, 3, json!({})).await.header;
    assert_eq!(after, before);
    // A queued job: cancelled before it starts, answered at once; then the running one.
    let big = json!({"setup": "phantom", "model": "teapot", "size": 512});
    send(&mut ws, Kind::Setup, 60, big).await;
    send(
        &mut ws,
        Kind::Setup,
        61,
        json!({"setup": "phantom", "model": "sphere", "size": 16}),
    )
    .await;
    send(&mut ws, Kind::Cancel, 62, json!({"request": 61})).await;
    send(&mut ws, Kind::Cancel, 63, json!({"request": 60})).await;
    let mut cancelled = Vec::new();
    while cancelled.len() < 2 {
        let f = recv(&mut ws).await.expect("connection closed");
        assert_ne!(f.kind, Kind::Changed, "{}", f.header);
        if f.kind == Kind::Error {
            assert_eq!(f.header["cancelled"], true, "{}", f.header);
            cancelled.push(f.request);
        }
    }
    cancelled.sort_unstable();
    assert_eq!(cancelled, [60, 61]);
    assert_eq!(
        ask(&mut ws, Kind::ListObjects, 4, json!({})).await.header,
        before
    );
    // A short edit: its Changed, and no Progress before it.
    send(
        &mut ws,
        Kind::MoveControlPoints,
        70,
        json!({"gesture": 9, "map": 2, "points": [[171, 0.1, 0.1, 0.1]]}),
    )
    .await;
    loop {
        let f = recv(&mut ws).await.expect("connection closed");
        assert_ne!(f.kind, Kind::Progress, "a short edit sends no progress");
        if f.kind == Kind::Changed {
            assert_eq!(f.header["request"], 70);
            break;
        }
    }
}

/// The mesh FFD set-up: Feng's identity lattice around a generated box with the page's
/// degrees and counts, and the deformed mesh; a control point moved deforms the mesh; the
/// STEP download of the deformed mesh is the accurate FFD with the Fig. 7 cube's 24 faces on
/// a closed shell; bad degrees are refused naming the axis.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn mesh_ffd_setup_moves_the_mesh_and_downloads_its_step() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    send(
        &mut ws,
        Kind::Setup,
        2,
        json!({"setup": "mesh", "shape": "box"}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    let mesh = c.header["added"][0].as_u64().unwrap();
    send(
        &mut ws,
        Kind::Setup,
        3,
        json!({"setup": "mesh-ffd", "mesh": mesh, "degree": [2, 2, 5], "counts": [4, 4, 9]}),
    )
    .await;
    let e = reply(&mut ws, 3).await;
    assert_eq!(e.kind, Kind::Error);
    assert!(
        e.header["message"].as_str().unwrap().contains("axis 2"),
        "{}",
        e.header
    );
    send(
        &mut ws,
        Kind::Setup,
        4,
        json!({"setup": "mesh-ffd", "mesh": mesh, "degree": [2, 2, 2], "counts": [4, 4, 4]}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    let (lattice, deformed) = (
        c.header["added"][0].as_u64().unwrap(),
        c.header["added"][1].as_u64().unwrap(),
    );
    let l = ask(&mut ws, Kind::GetLattice, 5, json!({"map": lattice})).await;
    assert_eq!(l.header["counts"], json!([4, 4, 4]));
    let pts = read_f32(&l.payload);
    // End-interpolating: the corner control points are the box's corners.
    assert_eq!(&pts[..3], &[-0.4f32, -0.4, -0.4]);
    assert_eq!(&pts[63 * 3..], &[0.4f32, 0.4, 0.4]);
    let m0 = ask(&mut ws, Kind::GetMesh, 6, json!({"id": deformed})).await;
    send(
        &mut ws,
        Kind::MoveControlPoints,
        7,
        json!({"gesture": 1, "map": lattice, "points": [[63, 0.7, 0.6, 0.5]]}),
    )
    .await;
    let c = recv_kind(&mut ws, Kind::Changed).await;
    assert!(
        c.header["modified"]
            .as_array()
            .unwrap()
            .contains(&json!(deformed))
    );
    let m1 = ask(&mut ws, Kind::GetMesh, 8, json!({"id": deformed})).await;
    let (a, b) = (
        read_f32(&m0.payload[..8 * 12]),
        read_f32(&m1.payload[..8 * 12]),
    );
    // The box's corner at the moved control point follows it; the opposite one stays.
    let corner = |v: &[f32], p: [f32; 3]| {
        (0..8).find(|&i| (0..3).all(|c| (v[3 * i + c] - p[c]).abs() < 1e-6))
    };
    let far = corner(&a, [0.4, 0.4, 0.4]).expect("the box has its corner");
    assert_eq!(&b[3 * far..3 * far + 3], &[0.7f32, 0.6, 0.5]);
    let near = corner(&a, [-0.4, -0.4, -0.4]).unwrap();
    assert_eq!(&b[3 * near..3 * near + 3], &[-0.4f32, -0.4, -0.4]);
    // The STEP download.
    let t = s.token();
    let get = format!(
        "GET /{t}/download/{deformed}/bent.step?page=1&request=9 HTTP/1.1\r\nHost: {}\r\nConnection: close\r\n\r\n",
        s.addr()
    );
    let mut conn = tokio::net::TcpStream::connect(s.addr()).await.unwrap();
    conn.write_all(get.as_bytes()).await.unwrap();
    let mut body = Vec::new();
    conn.read_to_end(&mut body).await.unwrap();
    let text = String::from_utf8_lossy(&body);
    assert!(
        text.starts_with("HTTP/1.1 200"),
        "{}",
        &text[..text.len().min(300)]
    );
    assert_eq!(text.matches("=ADVANCED_FACE(").count(), 24);
    assert_eq!(text.matches("=MANIFOLD_SOLID_BREP(").count(), 1);
    assert!(text.contains("END-ISO-10303-21;"));
}

/// The enclosed volume and the number of edges not shared by exactly two triangles of a
/// [`Kind::MeshData`] frame (positions, normals, then triangle indices).
fn volume_and_open_edges(f: &Frame) -> (f64, usize) {
    let nv = f.header["vertices"].as_u64().unwrap() as usize;
    let nt = f.header["triangles"].as_u64().unwrap() as usize;
    let p = read_f32(&f.payload[..nv * 12]);
    let idx: Vec<usize> = f.payload[nv * 24..nv * 24 + nt * 12]
        .chunks_exact(4)
        .map(|b| u32::from_le_bytes(b.try_into().unwrap()) as usize)
        .collect();
    let at = |i: usize| glam::DVec3::new(p[3 * i].into(), p[3 * i + 1].into(), p[3 * i + 2].into());
    let mut edges = std::collections::HashMap::new();
    let mut volume = 0.0;
    for t in idx.chunks_exact(3) {
        volume += at(t[0]).dot(at(t[1]).cross(at(t[2]))) / 6.0;
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *edges.entry((a.min(b), a.max(b))).or_insert(0) += 1;
        }
    }
    (volume, edges.values().filter(|&&n| n != 2).count())
}

/// Sculpting from a page: a mesh made sculptable, a stroke sent as many segments of one
/// gesture (coalesced into fewer edits, none dropped) cuts a closed groove, one undo takes
/// the whole stroke back bit for bit, a mesh object works as a brush, and bad brushes are
/// refused by name.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_sculpt_stroke_cuts_the_mesh_and_undoes_in_one_step() {
    let dir = tempfile::tempdir().unwrap();
    let s = studio(dir.path(), 1 << 20).await;
    let mut ws = connect(&s).await;
    send(
        &mut ws,
        Kind::Setup,
        2,
        json!({"setup": "mesh", "shape": "sphere"}),
    )
    .await;
    let sphere = recv_kind(&mut ws, Kind::Changed).await.header["added"][0]
        .as_u64()
        .unwrap();
    send(
        &mut ws,
        Kind::Setup,
        3,
        json!({"setup": "sculpt", "mesh": sphere, "grid": 64}),
    )
    .await;
    let id = recv_kind(&mut ws, Kind::Changed).await.header["added"][0]
        .as_u64()
        .unwrap();
    let m0 = ask(&mut ws, Kind::GetMesh, 4, json!({"id": id})).await;
    let (v0, open0) = volume_and_open_edges(&m0);
    assert_eq!(open0, 0, "the sculpt object's mesh is closed");
    // A stroke across the sphere's +z pole (radius 0.5), in 24 segments.
    let n = 24;
    let at = |k: usize| [-0.3 + 0.6 * k as f64 / n as f64, 0.0, 0.5];
    for k in 0..n {
        send(
            &mut ws,
            Kind::Command,
            100 + k as u32,
            json!({"command": "sculpt", "gesture": 7, "id": id, "brush": "sphere",
                   "op": "subtract", "size": 0.15, "points": [at(k), at(k + 1)]}),
        )
        .await;
    }
    send(&mut ws, Kind::EndGesture, 999, json!({"gesture": 7})).await;
    let mut edits = 0;
    loop {
        let c = recv_kind(&mut ws, Kind::Changed).await;
        match c.header["edit"].as_str().unwrap() {
            "sculpt" => edits += 1,
            "end-gesture" => break,
            e => panic!("unexpected edit {e}"),
        }
    }
    assert!((1..=n).contains(&edits), "{edits} edits for {n} segments");
    let m1 = ask(&mut ws, Kind::GetMesh, 5, json!({"id": id})).await;
    let (v1, open1) = volume_and_open_edges(&m1);
    assert_eq!(open1, 0, "the sculpted mesh is closed");
    // The groove: a ball of radius 0.15 swept 0.6 along the pole removes a cap-shaped
    // trough; at least a third of the swept ball's half inside the sphere.
    let swept = std::f64::consts::PI * 0.15f64.powi(2) * 0.6
        + 4.0 / 3.0 * std::f64::consts::PI * 0.15f64.powi(3);
    assert!(v0 - v1 > swept / 6.0, "removed {} of {swept}", v0 - v1);
    assert!(v1 > 0.0);
    send(&mut ws, Kind::Undo, 6, json!({})).await;
    assert_eq!(
        recv_kind(&mut ws, Kind::Changed).await.header["edit"],
        "undo"
    );
    let m2 = ask(&mut ws, Kind::GetMesh, 7, json!({"id": id})).await;
    assert_eq!(m2.header, m0.header);
    assert!(
        m2.payload == m0.payload,
        "one undo restores the mesh bit for bit"
    );
    // The generated sphere itself as a brush (centred, unit reach, so size 0.2 is a ball of
    // radius 0.2), adding at the equator.
    send(
        &mut ws,
        Kind::Command,
        8,
        json!({"command": "sculpt", "id": id, "brush": {"mesh": sphere}, "op": "add",
               "size": 0.2, "points": [[0.5, 0, 0]]}),
    )
    .await;
    assert_eq!(
        recv_kind(&mut ws, Kind::Changed).await.header["edit"],
        "sculpt"
    );
    let (v3, open3) =
        volume_and_open_edges(&ask(&mut ws, Kind::GetMesh, 9, json!({"id": id})).await);
    assert_eq!(open3, 0);
    assert!(v3 > v0 + 0.005, "{v3} vs {v0}");
    // A brush that is not a mesh, and an unknown operation, are refused by name.
    send(
        &mut ws,
        Kind::Command,
        10,
        json!({"command": "sculpt", "id": id, "brush": {"mesh": 999}, "op": "add",
               "size": 0.2, "points": [[0.5, 0, 0]]}),
    )
    .await;
    let e = reply(&mut ws, 10).await;
    assert_eq!(e.kind, Kind::Error);
    assert!(
        e.header["message"].as_str().unwrap().contains("999"),
        "{}",
        e.header
    );
    send(
        &mut ws,
        Kind::Command,
        11,
        json!({"command": "sculpt", "id": id, "brush": "sphere", "op": "carve",
               "size": 0.2, "points": [[0.5, 0, 0]]}),
    )
    .await;
    let e = reply(&mut ws, 11).await;
    assert!(
        e.header["message"].as_str().unwrap().contains("carve"),
        "{}",
        e.header
    );
}
