//! `splat serve`: the viewer's render thread behind a small HTTP server, for GPUs in machines
//! without a display. The page (one HTML file, no build step, nothing fetched from elsewhere)
//! shows the running mean as it converges and steers it with the viewer's controls and keys.
//!
//! - `GET /` the page; `GET /state` the settings, the menus, the render status and the camera
//!   as JSON; `GET /frame?after=S` the newest frame past sequence number `S` as a PNG (waiting
//!   up to [`FRAME_WAIT`] for one, else 204: nothing new); `POST /settings` a JSON object of
//!   settings to change; `POST /input` a JSON list of navigation actions ([`Action`]).
//! - Every browser on a server sees and steers one accumulation: there is one render thread,
//!   and on a GPU machine one device whose time is best spent converging one image rather than
//!   several at a fraction of the rate each. A page pulls the newest frame when it has drawn the
//!   last, so a slow client gets fewer frames and the render loop never waits for anyone; a
//!   client that goes away leaves nothing behind (a request waits at most [`FRAME_WAIT`]).
//! - Security: the server binds to 127.0.0.1 unless told otherwise (another address needs
//!   `public` and prints a warning); every request carries the token printed at start; the
//!   server reads only the scene it was started with (no request names a file); bodies are
//!   at most [`MAX_BODY`] bytes, at most [`MAX_IN_FLIGHT`] requests run at once and at most
//!   [`MAX_PER_SECOND`] are accepted a second.

use crate::load::SceneInfo;
use crate::navigate::{Action, FLY_KEYS, JUMP_KEYS, KEY_BINDINGS, Navigation, fly_action, key_action};
use crate::settings::{Backend, LOOKS, ParamValue, Pipeline, RNGS, SHADOWS, Settings, is_count, look_name};
use crate::settings::{param_choices, param_value, rng_name, set_param, shadows_name};
use crate::worker::{FrameFeed, HostFrame, Target, Worker};
use crate::{BackendChoice, SceneArgs};
use anyhow::{Context, Result, bail};
use serde_json::{Value, json};
use splat_core::MethodId;
use splat_core::catalogue::Param;
use splat_gpu::{AccumulationFormat, DisplayMode, GpuContext};
use std::io::Read;
use std::net::{IpAddr, SocketAddr};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};
use std::time::{Duration, Instant};

/// The page: HTML, CSS and JavaScript in one file.
const PAGE: &str = include_str!("serve/page.html");

/// Longest wait of a `/frame` request for a new frame.
pub const FRAME_WAIT: Duration = Duration::from_secs(5);
/// Largest request body (a settings change or a batch of input events).
pub const MAX_BODY: usize = 16 * 1024;
/// Requests handled at once; more are answered 503.
pub const MAX_IN_FLIGHT: usize = 32;
/// Requests accepted a second; more are answered 429.
pub const MAX_PER_SECOND: usize = 600;
/// Largest view, in pixels a side.
const MAX_SIZE: u32 = 4096;

/// The command line of `splat serve`.
#[derive(clap::Args, Clone, Debug)]
pub struct ServeArgs {
    /// The scene and how it renders.
    #[command(flatten)]
    pub scene: SceneArgs,
    /// Width of the view in pixels at render scale 1.
    #[arg(long, default_value_t = 960)]
    pub width: u32,
    /// Height of the view in pixels at render scale 1.
    #[arg(long, default_value_t = 600)]
    pub height: u32,
    /// Address to listen on: loopback unless --public is given too.
    #[arg(long, default_value = "127.0.0.1")]
    pub bind: IpAddr,
    /// Port to listen on (0: any free port; the URL printed at start names it).
    #[arg(long, default_value_t = 8080)]
    pub port: u16,
    /// Allow --bind to a non-loopback address: whoever reaches it with the token steers the render.
    #[arg(long)]
    pub public: bool,
}

/// Serve `args`' scene until the process is stopped.
pub fn run(args: &ServeArgs) -> Result<()> {
    if !(8..=MAX_SIZE).contains(&args.width) || !(8..=MAX_SIZE).contains(&args.height) {
        bail!("--width and --height must be 8 to {MAX_SIZE} pixels");
    }
    if !args.bind.is_loopback() && !args.public {
        bail!("--bind {} is not a loopback address: add --public to serve other machines", args.bind);
    }
    let loaded = args.scene.load()?;
    let options = args.scene.options(None);
    let (gpu, backend, note) = gpu_for(args.scene.backend);
    let (nav, settings) = options.start(loaded.info, &loaded.world.lighting, backend);
    let session = Session {
        nav,
        settings,
        size: [args.width, args.height],
        note,
        gpu_available: gpu.is_some(),
        worker: Worker::spawn(loaded.world, gpu, None, || {}),
    };
    let server = tiny_http::Server::http(SocketAddr::new(args.bind, args.port))
        .map_err(|e| anyhow::anyhow!("{e}"))
        .with_context(|| format!("cannot listen on {}:{}", args.bind, args.port))?;
    let port = server.server_addr().to_ip().map_or(args.port, |a| a.port());
    let token = token()?;
    if !args.bind.is_loopback() {
        eprintln!(
            "warning: serving on {} (--public): anyone who can reach it and has the token steers the render",
            args.bind
        );
    }
    // An unspecified address (0.0.0.0, ::) listens on loopback too: the URL names loopback.
    let host = match args.bind {
        IpAddr::V4(ip) if ip.is_unspecified() => IpAddr::V4(std::net::Ipv4Addr::LOCALHOST),
        IpAddr::V6(ip) if ip.is_unspecified() => IpAddr::V6(std::net::Ipv6Addr::LOCALHOST),
        ip => ip,
    };
    println!("splat serve: http://{}/?token={token}", SocketAddr::new(host, port));
    println!("splat serve: {} ({})", session.nav.scene().name, session.note);
    let state = Arc::new(State {
        feed: session.worker.feed(),
        png: Mutex::new(None),
        session: Mutex::new(session),
        token,
        bounds: Bounds::default(),
    });
    state.session().post();
    for request in server.incoming_requests() {
        if let Some(refusal) = state.bounds.admit() {
            let _ = request.respond(refusal);
            continue;
        }
        let state = state.clone();
        std::thread::spawn(move || {
            let _counted = InFlight(&state.bounds.in_flight);
            state.handle(request);
        });
    }
    Ok(())
}

/// The GPU context `choice` asks for (`auto`: a hardware GPU only), the backend frames start
/// on, and why.
fn gpu_for(choice: BackendChoice) -> (Option<GpuContext>, Backend, String) {
    let gpu = match choice {
        BackendChoice::Cpu => Err(None),
        BackendChoice::Auto => match GpuContext::hardware() {
            Ok(Some(ctx)) => Ok(ctx),
            Ok(None) => return (None, Backend::Cpu, "no hardware GPU: rendering on the CPU".into()),
            Err(e) => Err(Some(e.to_string())),
        },
        BackendChoice::Gpu => GpuContext::new().map_err(|e| Some(e.to_string())),
    };
    let (backend, note) = choice.resolve(gpu.as_ref().ok().map(|ctx| &ctx.info), &gpu);
    (gpu.ok(), backend, note)
}

/// 128 random bits from the operating system, in hex: the token every request carries.
fn token() -> Result<String> {
    let mut bytes = [0u8; 16];
    std::fs::File::open("/dev/urandom")
        .and_then(|mut f| f.read_exact(&mut bytes))
        .context("no random token without /dev/urandom")?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// What the server holds: the session, the token and the request bounds.
struct State {
    session: Mutex<Session>,
    feed: FrameFeed,
    /// The newest frame encoded as PNG, shared by every page that asks for it.
    png: Mutex<Option<(u64, Arc<Vec<u8>>)>>,
    token: String,
    bounds: Bounds,
}

/// The requests running and those accepted this second.
struct Bounds {
    in_flight: AtomicUsize,
    /// The start of the current second and the requests accepted in it.
    rate: Mutex<(Instant, usize)>,
}

impl Default for Bounds {
    fn default() -> Self {
        Self { in_flight: AtomicUsize::new(0), rate: Mutex::new((Instant::now(), 0)) }
    }
}

impl Bounds {
    /// Count a request in ([`InFlight`] counts it out), or the refusal when
    /// [`MAX_PER_SECOND`] arrived this second or [`MAX_IN_FLIGHT`] run.
    fn admit(&self) -> Option<Response> {
        self.admit_at(Instant::now())
    }

    /// [`Bounds::admit`] at time `now`.
    fn admit_at(&self, now: Instant) -> Option<Response> {
        {
            let mut rate = self.rate.lock().unwrap_or_else(|p| p.into_inner());
            if now.saturating_duration_since(rate.0) >= Duration::from_secs(1) {
                *rate = (now, 0);
            }
            if rate.1 >= MAX_PER_SECOND {
                return Some(error(429, "too many requests this second"));
            }
            rate.1 += 1;
        }
        if self.in_flight.fetch_add(1, Ordering::SeqCst) >= MAX_IN_FLIGHT {
            self.in_flight.fetch_sub(1, Ordering::SeqCst);
            return Some(error(503, "too many requests at once"));
        }
        None
    }
}

/// The render and everything the page steers.
struct Session {
    nav: Navigation,
    settings: Settings,
    /// The view's size at render scale 1.
    size: [u32; 2],
    /// Where frames render, and why.
    note: String,
    gpu_available: bool,
    worker: Worker,
}

/// One request counted in [`Bounds::admit`], counted out when it ends however it ends.
struct InFlight<'a>(&'a AtomicUsize);

impl Drop for InFlight<'_> {
    fn drop(&mut self) {
        self.0.fetch_sub(1, Ordering::SeqCst);
    }
}

type Response = tiny_http::Response<std::io::Cursor<Vec<u8>>>;

/// A response of `status` with `body` of `content_type`.
fn reply(status: u16, content_type: &str, body: Vec<u8>) -> Response {
    let header = tiny_http::Header::from_bytes("Content-Type", content_type).expect("an ASCII header");
    let cache = tiny_http::Header::from_bytes("Cache-Control", "no-store").expect("an ASCII header");
    tiny_http::Response::from_data(body).with_status_code(status).with_header(header).with_header(cache)
}

/// A plain-text error of `status`.
fn error(status: u16, message: &str) -> Response {
    reply(status, "text/plain; charset=utf-8", format!("{message}\n").into_bytes())
}

/// A JSON response.
fn json_reply(value: &Value) -> Response {
    reply(200, "application/json", value.to_string().into_bytes())
}

impl State {
    fn session(&self) -> std::sync::MutexGuard<'_, Session> {
        self.session.lock().unwrap_or_else(|poisoned| poisoned.into_inner())
    }

    /// Answer one request.
    fn handle(&self, mut request: tiny_http::Request) {
        let url = request.url().to_string();
        let (path, query) = url.split_once('?').unwrap_or((&url, ""));
        let param =
            |name: &str| query.split('&').filter_map(|kv| kv.split_once('=')).find(|(k, _)| *k == name).map(|(_, v)| v);
        let response = if !param("token").is_some_and(|t| same(t.as_bytes(), self.token.as_bytes())) {
            error(403, "missing or wrong token: open the URL splat serve printed")
        } else {
            use tiny_http::Method::{Get, Post};
            match (request.method(), path) {
                (Get, "/") => reply(200, "text/html; charset=utf-8", PAGE.as_bytes().to_vec()),
                (Get, "/state") => json_reply(&self.session().state()),
                (Get, "/frame") => self.frame(param("after").and_then(|a| a.parse().ok()).unwrap_or(0)),
                (Post, "/settings" | "/input") => match body(&mut request) {
                    Ok(value) => self.change(path, &value),
                    Err(response) => response,
                },
                (_, "/" | "/state" | "/frame" | "/settings" | "/input") => error(405, "method not allowed"),
                _ => error(404, "no such page"),
            }
        };
        let _ = request.respond(response);
    }

    /// `/settings` or `/input` with `value`: the new state, or why nothing changed.
    fn change(&self, path: &str, value: &Value) -> Response {
        let mut session = self.session();
        let changed = match path {
            "/settings" => session.apply_settings(value),
            _ => session.apply_input(value),
        };
        match changed {
            Ok(()) => {
                session.post();
                json_reply(&session.state())
            }
            Err(message) => error(400, &message),
        }
    }

    /// The newest frame past `after` as a PNG, with its sequence number, job, frame count and
    /// status in headers.
    fn frame(&self, after: u64) -> Response {
        let frame = self.feed.wait(after, FRAME_WAIT);
        if frame.sequence <= after {
            // Nothing new (paused, converged, or a slow frame): ask again.
            return reply(204, "image/png", Vec::new());
        }
        let png = match self.png(&frame) {
            Ok(png) => png,
            Err(e) => return error(500, &format!("the frame could not be encoded: {e}")),
        };
        let mut response = reply(200, "image/png", png.to_vec());
        let status = self.feed.status();
        for (name, value) in [
            ("X-Sequence", frame.sequence.to_string()),
            ("X-Job", frame.job.to_string()),
            ("X-Frames", frame.frames.to_string()),
            ("X-Fps", format!("{:.1}", status.frames_per_second)),
            ("X-Rmse", status.rmse.map_or(String::new(), |r| format!("{r:.6}"))),
        ] {
            response.add_header(tiny_http::Header::from_bytes(name, value).expect("an ASCII header"));
        }
        response
    }

    /// `frame` as a PNG, encoded once for every page that asks for it.
    fn png(&self, frame: &HostFrame) -> Result<Arc<Vec<u8>>, png::EncodingError> {
        let mut cache = self.png.lock().unwrap_or_else(|p| p.into_inner());
        if let Some((sequence, png)) = cache.as_ref()
            && *sequence == frame.sequence
        {
            return Ok(png.clone());
        }
        let png = Arc::new(encode_png(frame)?);
        *cache = Some((frame.sequence, png.clone()));
        Ok(png)
    }
}

/// `frame`'s RGBA8 texels as a PNG (fast compression: lossless, and quick enough to stream).
fn encode_png(frame: &HostFrame) -> Result<Vec<u8>, png::EncodingError> {
    let mut bytes = Vec::new();
    let mut encoder = png::Encoder::new(&mut bytes, frame.width, frame.height);
    encoder.set_color(png::ColorType::Rgba);
    encoder.set_depth(png::BitDepth::Eight);
    encoder.set_compression(png::Compression::Fast);
    encoder.write_header()?.write_image_data(&frame.rgba)?;
    Ok(bytes)
}

/// Whether `a` equals `b`, in a time that does not depend on where they first differ.
fn same(a: &[u8], b: &[u8]) -> bool {
    a.len() == b.len() && a.iter().zip(b).fold(0u8, |d, (x, y)| d | (x ^ y)) == 0
}

/// The request's body as JSON, at most [`MAX_BODY`] bytes.
fn body(request: &mut tiny_http::Request) -> Result<Value, Response> {
    if request.body_length().is_some_and(|n| n > MAX_BODY) {
        return Err(error(413, &format!("a request body is at most {MAX_BODY} bytes")));
    }
    let mut bytes = Vec::new();
    let read = request.as_reader().take(MAX_BODY as u64 + 1).read_to_end(&mut bytes);
    if read.is_err() || bytes.len() > MAX_BODY {
        return Err(error(413, &format!("a request body is at most {MAX_BODY} bytes")));
    }
    serde_json::from_slice(&bytes).map_err(|e| error(400, &format!("the body is not JSON: {e}")))
}

impl Session {
    /// Post the job of the current camera and settings (nothing when neither changed).
    fn post(&mut self) {
        let [w, h] = self.size;
        let (camera, _) = self.nav.camera([w as f32, h as f32], self.settings.scale);
        self.nav.post(&mut self.worker, camera, &mut self.settings, || Target::Host);
    }

    /// Everything the page shows: the scene, the settings and their menus, the render's
    /// status, the camera (as a cameras.json entry) and the keys.
    fn state(&self) -> Value {
        let s = &self.settings;
        let status = self.worker.posted_status().unwrap_or_default();
        let camera =
            self.worker.posted().map(|p| splat_io::cameras::CameraEntry::from_camera(0, "splat serve", &p.camera));
        let SceneInfo { name, particles, sh_degree, views, .. } = self.nav.scene();
        json!({
            "scene": { "name": name, "particles": particles, "sh_degree": sh_degree, "views": views.len() },
            "backend_note": self.note,
            "settings": settings_json(s),
            "menus": menus(self.gpu_available),
            "status": {
                "job": status.job,
                "frames": status.frames,
                "frames_per_second": status.frames_per_second,
                "rmse": status.rmse,
                "error": status.error,
                "idle": status.idle,
            },
            "camera": camera,
            "view": self.nav.view(),
            "keys": KEY_BINDINGS,
            "key_names": key_names(),
        })
    }

    /// Change the settings `value` names (an object of [`settings_json`]'s keys).
    fn apply_settings(&mut self, value: &Value) -> Result<(), String> {
        self.settings = changed(&self.settings, value, self.gpu_available)?;
        Ok(())
    }

    /// Apply a list of navigation actions: `{"do": "rotate", "dx", "dy"}`, `{"do": "pan",
    /// "dx", "dy", "height"}`, `{"do": "zoom", "steps"}`, `{"do": "key", "key"}` (a key that
    /// jumps, or a fly key held for `seconds`, faster with `fast`).
    fn apply_input(&mut self, value: &Value) -> Result<(), String> {
        let actions = value.as_array().ok_or("the input is a JSON list of actions")?;
        if actions.len() > 256 {
            return Err("at most 256 actions a request".into());
        }
        let parsed: Vec<Action> = actions.iter().map(action).collect::<Result<_, _>>()?;
        for a in parsed {
            self.nav.act(a, &mut self.settings);
        }
        Ok(())
    }
}

/// `settings` with the changes `value` names (an object of [`settings_json`]'s keys), all or
/// none: the first bad key or value is the error.
fn changed(settings: &Settings, value: &Value, gpu_available: bool) -> Result<Settings, String> {
    let object = value.as_object().ok_or("the settings are a JSON object")?;
    let mut s = settings.clone();
    for (key, v) in object {
        set(&mut s, key, v, gpu_available).map_err(|e| format!("{key}: {e}"))?;
    }
    s.params.validate().map_err(|e| e.to_string())?;
    Ok(s)
}

/// The names of the keys the page sends (lower case, as its key events name them): the fly
/// keys and the keys that jump.
fn key_names() -> Vec<String> {
    FLY_KEYS.iter().map(char::to_string).chain(JUMP_KEYS.iter().map(|k| k.to_ascii_lowercase())).collect()
}

/// The action one input event asks for.
fn action(event: &Value) -> Result<Action, String> {
    let number = |key: &str| {
        event
            .get(key)
            .and_then(Value::as_f64)
            .filter(|v| v.is_finite() && v.abs() <= 1e6)
            .map(|v| v as f32)
            .ok_or_else(|| format!("an input event needs a finite number \"{key}\": {event}"))
    };
    match event.get("do").and_then(Value::as_str) {
        Some("rotate") => Ok(Action::Rotate(number("dx")?, number("dy")?)),
        Some("pan") => Ok(Action::Pan(number("dx")?, number("dy")?, number("height")?.max(1.0))),
        Some("zoom") => Ok(Action::Zoom(number("steps")?.clamp(-50.0, 50.0))),
        Some("key") => {
            let key = event.get("key").and_then(Value::as_str).ok_or("a key event needs \"key\"")?;
            if let Some(action) = key_action(key) {
                return Ok(action);
            }
            let held = FLY_KEYS.map(|c| key.eq_ignore_ascii_case(&c.to_string()));
            let fast = event.get("fast").and_then(Value::as_bool).unwrap_or(false);
            let seconds = number("seconds").unwrap_or(1.0 / 30.0).clamp(0.0, 0.1);
            fly_action(held, fast, seconds)
                .ok_or_else(|| format!("no key \"{key}\": the keys are {}", KEY_BINDINGS.join("; ")))
        }
        _ => Err(format!("an input event is {{\"do\": \"rotate\" | \"pan\" | \"zoom\" | \"key\", …}}: {event}")),
    }
}

/// A parameter's value as JSON: a number, a choice's name or a switch.
fn param_json(value: ParamValue) -> Value {
    match value {
        ParamValue::Number(x) => json!(x),
        ParamValue::Choice(name) => json!(name),
        ParamValue::Switch(on) => json!(on),
    }
}

/// The parameter value a JSON value gives.
fn param_of_json(v: &Value) -> Result<ParamValue, String> {
    match v {
        Value::Number(x) => x.as_f64().map(ParamValue::Number).ok_or_else(|| format!("{v} is not a number")),
        Value::String(name) => Ok(ParamValue::Choice(name.clone())),
        Value::Bool(on) => Ok(ParamValue::Switch(*on)),
        _ => Err(format!("a parameter is a number, a name or true / false, not {v}")),
    }
}

/// The settings the page shows and sets.
fn settings_json(s: &Settings) -> Value {
    let params: serde_json::Map<String, Value> =
        Param::ALL.iter().map(|&p| (p.info().flag.to_string(), param_json(param_value(&s.params, p)))).collect();
    json!({
        "backend": match s.backend { Backend::Gpu => "gpu", Backend::Cpu => "cpu" },
        "pipeline": s.pipeline.name(),
        "trace": s.trace.name(),
        "raster": s.raster.name(),
        "params": params,
        "rng": rng_name(s.rng),
        "seed": s.seed,
        "accumulation": s.accumulation.name(),
        "look": look_name(s.look),
        "shadows": shadows_name(s.shadows),
        "display": s.display.mode.name(),
        "scale": s.scale,
        "max_frames": s.max_frames,
        "rmse": s.rmse,
        "paused": s.paused,
    })
}

/// The choices of each menu of the page, and each numeric parameter's limits and methods.
fn menus(gpu_available: bool) -> Value {
    let names = |ids: Vec<MethodId>| ids.into_iter().map(MethodId::name).collect::<Vec<_>>();
    let defaults = splat_core::Parameters::default();
    let params: Vec<Value> = Param::ALL
        .iter()
        .map(|&p| {
            let info = p.info();
            let readers: Vec<&str> = MethodId::ALL.iter().filter(|m| m.reads(p)).map(|m| m.name()).collect();
            let mut entry = json!({ "name": info.flag, "label": info.label, "methods": readers });
            match (param_value(&defaults, p), info.limits) {
                (ParamValue::Number(_), Some(limits)) => {
                    entry["kind"] = json!("number");
                    entry["min"] = json!(limits.min);
                    entry["max"] = json!(limits.max);
                    entry["integer"] = json!(is_count(p));
                }
                (ParamValue::Choice(_), _) => {
                    entry["kind"] = json!("choice");
                    entry["choices"] = json!(param_choices(p));
                }
                _ => entry["kind"] = json!("switch"),
            }
            entry
        })
        .collect();
    json!({
        "backend": if gpu_available { vec!["gpu", "cpu"] } else { vec!["cpu"] },
        "pipeline": Pipeline::ALL.map(Pipeline::name),
        "trace": names(Settings::trace_menu()),
        "raster": names(Settings::raster_menu()),
        "rng": RNGS.map(rng_name),
        "accumulation": AccumulationFormat::ALL.map(AccumulationFormat::name),
        "look": LOOKS.map(look_name),
        "shadows": SHADOWS.map(shadows_name),
        "display": DisplayMode::ALL.map(DisplayMode::name),
        "params": params,
    })
}

/// The one of the menu `all` that `v` names by `name`.
fn one_of<T: Copy>(v: &Value, all: &[T], name: fn(T) -> &'static str) -> Result<T, String> {
    let chosen = v.as_str().ok_or_else(|| format!("expected a name, got {v}"))?;
    all.iter().copied().find(|&x| name(x) == chosen).ok_or_else(|| {
        let names: Vec<&str> = all.iter().map(|&x| name(x)).collect();
        format!("\"{chosen}\" is not one of {}", names.join(", "))
    })
}

/// Set `key` of the settings to `v`.
fn set(s: &mut Settings, key: &str, v: &Value, gpu_available: bool) -> Result<(), String> {
    let text = || v.as_str().ok_or_else(|| format!("expected a name, got {v}"));
    let flag = || v.as_bool().ok_or_else(|| format!("expected true or false, got {v}"));
    let number = || v.as_f64().filter(|x| x.is_finite()).ok_or_else(|| format!("expected a number, got {v}"));
    match key {
        "backend" => match text()? {
            "cpu" => s.backend = Backend::Cpu,
            "gpu" if gpu_available => s.backend = Backend::Gpu,
            "gpu" => return Err("this server has no GPU context".into()),
            other => return Err(format!("\"{other}\" is not gpu or cpu")),
        },
        "pipeline" => s.pipeline = one_of(v, &Pipeline::ALL, Pipeline::name)?,
        "trace" => s.trace = one_of(v, &Settings::trace_menu(), MethodId::name)?,
        "raster" => s.raster = one_of(v, &Settings::raster_menu(), MethodId::name)?,
        "rng" => s.rng = one_of(v, &RNGS, rng_name)?,
        "accumulation" => s.accumulation = one_of(v, &AccumulationFormat::ALL, AccumulationFormat::name)?,
        "look" => s.look = one_of(v, &LOOKS, look_name)?,
        "shadows" => s.shadows = one_of(v, &SHADOWS, shadows_name)?,
        "display" => s.display.mode = one_of(v, &DisplayMode::ALL, DisplayMode::name)?,
        "scale" => s.scale = (number()? as f32).clamp(0.125, 1.0),
        "max_frames" => s.max_frames = number()?.clamp(1.0, 1e6) as u32,
        "seed" => s.seed = number()?.clamp(0.0, f64::from(u32::MAX)) as u32,
        "rmse" => s.rmse = flag()?,
        "paused" => s.paused = flag()?,
        "params" => {
            let object = v.as_object().ok_or("the parameters are a JSON object")?;
            for (name, value) in object {
                let p = Param::ALL.into_iter().find(|p| p.info().flag == name);
                let p = p.ok_or_else(|| format!("no parameter {name}"))?;
                set_param(&mut s.params, p, param_of_json(value)?)?;
            }
        }
        _ => return Err("not a setting".into()),
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use splat_core::RenderSettings;
    use splat_core::lighting::Lighting;

    fn settings() -> Settings {
        Settings::new(RenderSettings::default(), &Lighting::default(), Backend::Cpu)
    }

    /// Every choice of every menu the page offers is accepted and read back as chosen; a
    /// name outside a menu is refused, naming the menu.
    #[test]
    fn every_menu_choice_round_trips_and_others_are_refused() {
        let menus = menus(false);
        for key in ["pipeline", "trace", "raster", "rng", "accumulation", "look", "shadows", "display", "backend"] {
            for choice in menus[key].as_array().unwrap() {
                let mut s = settings();
                set(&mut s, key, choice, false).unwrap_or_else(|e| panic!("{key} = {choice}: {e}"));
                assert_eq!(&settings_json(&s)[key], choice, "{key}");
            }
            let refused = set(&mut settings(), key, &json!("no-such-choice"), false).unwrap_err();
            assert!(refused.contains("no-such-choice"), "{refused}");
        }
        assert!(set(&mut settings(), "backend", &json!("gpu"), false).unwrap_err().contains("no GPU"));
        assert_eq!(set(&mut settings(), "path", &json!("/etc/passwd"), false).unwrap_err(), "not a setting");
    }

    /// Every parameter is set by its CLI name with the values its menu entry offers (numbers
    /// within the catalogue's limits, each choice, both switch states) and reads back as set;
    /// a number above its limit is refused, as a value of the wrong kind.
    #[test]
    fn parameters_are_set_by_name_within_their_limits() {
        let mut session_settings = settings();
        let menus = menus(false);
        for entry in menus["params"].as_array().unwrap() {
            let name = entry["name"].as_str().unwrap();
            let values = match entry["kind"].as_str().unwrap() {
                "number" => vec![entry["max"].clone()],
                "choice" => entry["choices"].as_array().unwrap().clone(),
                _ => vec![json!(false), json!(true)],
            };
            for value in values {
                let mut s = settings();
                set(&mut s, "params", &json!({ name: value }), false).unwrap_or_else(|e| panic!("{name}: {e}"));
                assert_eq!(settings_json(&s)["params"][name], value, "{name}");
            }
            if entry["kind"] == "number" {
                let above = entry["max"].as_f64().unwrap() + 1.0;
                let refused = changed(&settings(), &json!({ "params": { name: above } }), false);
                assert!(refused.is_err(), "{name} above its limit");
                let max = changed(&settings(), &json!({ "params": { name: entry["max"] } }), false);
                assert!(max.is_ok(), "{name} at its limit");
            }
            assert!(set(&mut settings(), "params", &json!({ name: [1] }), false).is_err(), "{name} took a list");
        }
        assert!(set(&mut session_settings, "params", &json!({ "no-such": 1 }), false).is_err());
        assert!(set(&mut session_settings, "rmse", &json!(1), false).is_err());
        assert!(set(&mut session_settings, "scale", &json!("big"), false).is_err());
        set(&mut session_settings, "scale", &json!(9.0), false).unwrap();
        assert_eq!(session_settings.scale, 1.0, "the render scale is clamped to the panel's range");
    }

    /// At most [`MAX_IN_FLIGHT`] requests run at once (one more is refused until one ends) and
    /// at most [`MAX_PER_SECOND`] are accepted in a second.
    #[test]
    fn requests_are_bounded_at_once_and_per_second() {
        let bounds = Bounds::default();
        let now = bounds.rate.lock().unwrap().0;
        let admitted: Vec<_> = (0..MAX_IN_FLIGHT).map(|_| bounds.admit_at(now)).collect();
        assert!(admitted.iter().all(Option::is_none));
        assert_eq!(bounds.admit_at(now).map(|r| r.status_code().0), Some(503));
        drop(InFlight(&bounds.in_flight));
        assert!(bounds.admit_at(now).is_none(), "a request that ended makes room");
        for _ in 0..MAX_IN_FLIGHT {
            drop(InFlight(&bounds.in_flight));
        }
        // 34 counted this second so far (the refused one too).
        let accepted = (0..2 * MAX_PER_SECOND)
            .filter(|_| {
                let admitted = bounds.admit_at(now).is_none();
                if admitted {
                    drop(InFlight(&bounds.in_flight));
                }
                admitted
            })
            .count();
        assert_eq!(accepted, MAX_PER_SECOND - MAX_IN_FLIGHT - 2, "requests beyond the second's budget pass");
        assert_eq!(bounds.admit_at(now).map(|r| r.status_code().0), Some(429));
        assert!(bounds.admit_at(now + Duration::from_secs(1)).is_none(), "the next second has its own budget");
    }

    /// Input events become the window's actions; malformed ones are refused with the reason.
    #[test]
    fn input_events_are_the_windows_actions() {
        assert_eq!(action(&json!({"do": "rotate", "dx": 3, "dy": -2})), Ok(Action::Rotate(3.0, -2.0)));
        assert_eq!(action(&json!({"do": "key", "key": "n"})), Ok(Action::StepView(1)));
        assert_eq!(action(&json!({"do": "key", "key": "2"})), Ok(Action::Show(DisplayMode::ALL[1])));
        let Ok(Action::Fly(forward, right, up)) = action(&json!({"do": "key", "key": "W", "seconds": 0.1})) else {
            panic!("W does not fly")
        };
        assert_eq!((forward, right, up), (0.05, 0.0, 0.0));
        assert!(action(&json!({"do": "rotate", "dx": "x", "dy": 0})).unwrap_err().contains("dx"));
        assert!(action(&json!({"do": "rotate", "dx": 1e300, "dy": 0})).is_err(), "an absurd drag");
        assert!(action(&json!({"do": "key", "key": "z"})).unwrap_err().contains("no key"));
        for key in key_names() {
            assert!(action(&json!({"do": "key", "key": key})).is_ok(), "the page sends {key}, which does nothing");
        }
        assert!(action(&json!({"do": "open", "path": "/"})).is_err());
        assert!(same(b"abc", b"abc") && !same(b"abc", b"abd") && !same(b"abc", b"ab"));
    }
}
