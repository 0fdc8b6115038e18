//! The render thread: it owns the scene and its BVH, takes the newest [`Job`] the window (or
//! the page of `splat serve`) posts, folds frames into the view's accumulation and draws the
//! result into the job's [`Target`], so that the window stays responsive however long a frame
//! takes.
//!
//! A job that changes the scene's settings (kernel, hit distance, normals, iso threshold,
//! backend) rebuilds the BVH; one that changes the lighting (look, shadows, lights, materials)
//! relights the same BVH; one that changes the camera or what the frames are (method,
//! parameters, generator, seed, accumulation) restarts the accumulation; one that changes only
//! the display transform redraws what is accumulated.

use crate::accumulate::CpuAccumulation;
use crate::settings::Settings;
use splat_core::algorithm::{Algorithm, PreparedView};
use splat_core::frame::{Frames, RenderOutput};
use splat_core::trace::{Method, TraceScene};
use splat_core::{Camera, World};
use splat_gpu::{GpuContext, GpuTracer, ProgressiveTrace, TracePipeline, wgpu};
use std::sync::{Arc, Condvar, Mutex};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

/// What the window asks the render thread for.
#[derive(Clone)]
pub struct Job {
    /// The view's camera (its size is the texture's).
    pub camera: Camera,
    /// The panel's choices.
    pub settings: Settings,
    /// Where the view is drawn.
    pub target: Target,
    /// A new generation restarts the accumulation of the same view ("restart").
    pub generation: u64,
}

/// Where the render thread draws the view.
#[derive(Clone)]
pub enum Target {
    /// A texture of the window's device: `camera`'s size, [`TEXTURE_FORMAT`].
    Texture(wgpu::Texture),
    /// 8-bit RGBA rows in host memory, read with [`Worker::feed`] (the page of `splat
    /// serve`): the same display transform, read back from the device on the GPU.
    Host,
}

/// The view as the render thread last drew it into a [`Target::Host`].
#[derive(Clone, Debug, Default)]
pub struct HostFrame {
    /// Increases with every frame drawn (0: none yet).
    pub sequence: u64,
    /// The job it belongs to.
    pub job: u64,
    /// Frames accumulated in it.
    pub frames: u32,
    /// Width in pixels.
    pub width: u32,
    /// Height in pixels.
    pub height: u32,
    /// `width` × `height` RGBA8 texels, row after row, as a window would show them.
    pub rgba: Arc<Vec<u8>>,
}

/// The frames a worker draws into a [`Target::Host`] ([`Worker::feed`]).
#[derive(Clone)]
pub struct FrameFeed(Arc<Shared>);

impl FrameFeed {
    /// The newest frame once its sequence number passes `after`, waiting at most `timeout`
    /// for it (then the newest there is, perhaps older).
    pub fn wait(&self, after: u64, timeout: Duration) -> HostFrame {
        let frame = self.0.frame.lock().expect("lock");
        let (frame, _) = self.0.drawn.wait_timeout_while(frame, timeout, |f| f.sequence <= after).expect("lock");
        frame.clone()
    }

    /// The render thread's latest status.
    pub fn status(&self) -> Status {
        self.0.status()
    }
}

/// The format of the view's texture: the display's sRGB-encoded bytes, stored as they are
/// shown, in a texture that is *not* marked sRGB. egui-wgpu (0.37) treats every texture it
/// samples as gamma-encoded (`tex_gamma = sample_texture(in)` in its `egui.wgsl`) and does its
/// blending in gamma space; an `Rgba8UnormSrgb` texture would be decoded by the sampler once
/// more, and the window would show about value^2.2 of what `splat render` writes.
pub const TEXTURE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// How the render thread is doing, for the window's status lines.
#[derive(Clone, Debug, Default)]
pub struct Status {
    /// The job the frames belong to.
    pub job: u64,
    /// Frames accumulated.
    pub frames: u32,
    /// Frames per second over the last second of rendering.
    pub frames_per_second: f32,
    /// RMSE of the running mean against the exact image of the view, when asked for.
    pub rmse: Option<f64>,
    /// Why the job cannot render.
    pub error: Option<String>,
    /// Whether the accumulation is finished (converged, at the frame limit, or paused with at
    /// least one frame of the view to show).
    pub idle: bool,
}

/// The render thread and the channel to it.
pub struct Worker {
    shared: Arc<Shared>,
    thread: Option<JoinHandle<()>>,
    posted: Option<Posted>,
}

/// The last job [`Worker::post`] submitted: its number and what it asked for.
#[derive(Clone, Debug)]
pub struct Posted {
    /// The job's number.
    pub id: u64,
    /// Its camera.
    pub camera: Camera,
    /// Its settings.
    pub settings: Settings,
    /// Its generation (bumped by "restart").
    pub generation: u64,
}

#[derive(Default)]
struct Shared {
    control: Mutex<Control>,
    wake: Condvar,
    status: Mutex<Status>,
    frame: Mutex<HostFrame>,
    drawn: Condvar,
}

#[derive(Default)]
struct Control {
    job: Option<(u64, Job)>,
    quit: bool,
}

/// What the render thread does next.
enum Next {
    Quit,
    Same,
    New(u64, Box<Job>),
}

impl Shared {
    /// The newest job if it is not `current`; with `wait`, block until there is one.
    fn next(&self, current: u64, wait: bool) -> Next {
        let mut control = self.control.lock().expect("the window never panics holding the lock");
        loop {
            if control.quit {
                return Next::Quit;
            }
            match &control.job {
                Some((id, job)) if *id != current => return Next::New(*id, Box::new(job.clone())),
                _ if !wait => return Next::Same,
                _ => control = self.wake.wait(control).expect("lock"),
            }
        }
    }

    fn publish(&self, status: Status) {
        *self.status.lock().expect("lock") = status;
    }

    /// The latest status published.
    fn status(&self) -> Status {
        self.status.lock().expect("lock").clone()
    }

    /// Make `rgba` the newest host frame and wake whoever waits for one.
    fn publish_frame(&self, job: u64, frames: u32, (width, height): (u32, u32), rgba: Vec<u8>) {
        let mut frame = self.frame.lock().expect("lock");
        *frame = HostFrame { sequence: frame.sequence + 1, job, frames, width, height, rgba: Arc::new(rgba) };
        self.drawn.notify_all();
    }
}

impl Worker {
    /// Start the render thread on `world`: on `gpu` (the window's device) where the settings
    /// ask for it, on the CPU otherwise; `queue` uploads the CPU's images into a
    /// [`Target::Texture`] (a [`Target::Host`] needs none); `repaint` wakes the window when
    /// there is something new to show.
    pub fn spawn(
        world: World,
        gpu: Option<GpuContext>,
        queue: Option<wgpu::Queue>,
        repaint: impl Fn() + Send + 'static,
    ) -> Self {
        let shared = Arc::new(Shared::default());
        let thread = {
            let shared = shared.clone();
            let gpu: Gpu = gpu.ok_or_else(|| "no GPU context".to_string()).and_then(|ctx| {
                let pipeline = TracePipeline::new(&ctx).map_err(|e| e.to_string())?;
                Ok((ctx, pipeline))
            });
            std::thread::Builder::new()
                .name("splat view renderer".into())
                .spawn(move || Renderer { world, gpu, queue, shared, repaint: Box::new(repaint) }.run())
                .expect("the OS starts a thread")
        };
        Self { shared, thread: Some(thread), posted: None }
    }

    /// Submit a job of `camera`, `settings` and `generation` into `target` when it asks for
    /// anything the last one posted did not; the number of the job now asked for.
    pub fn post(
        &mut self,
        camera: Camera,
        settings: &Settings,
        generation: u64,
        target: impl FnOnce() -> Target,
    ) -> u64 {
        if let Some(p) = &self.posted
            && p.camera == camera
            && p.settings == *settings
            && p.generation == generation
        {
            return p.id;
        }
        let id = self.posted.as_ref().map_or(1, |p| p.id + 1);
        self.submit(id, Job { camera, settings: settings.clone(), target: target(), generation });
        self.posted = Some(Posted { id, camera, settings: settings.clone(), generation });
        id
    }

    /// The last job [`Worker::post`] submitted.
    pub fn posted(&self) -> Option<&Posted> {
        self.posted.as_ref()
    }

    /// The render thread's latest status once it is about the last job posted.
    pub fn posted_status(&self) -> Option<Status> {
        let status = self.status();
        (self.posted.as_ref().map(|p| p.id) == Some(status.job)).then_some(status)
    }

    /// Ask for `job` (numbered `id`, increasing), replacing any job not yet taken.
    fn submit(&self, id: u64, job: Job) {
        self.shared.control.lock().expect("lock").job = Some((id, job));
        self.shared.wake.notify_all();
    }

    /// The latest status.
    pub fn status(&self) -> Status {
        self.shared.status()
    }

    /// The frames drawn into a [`Target::Host`], to wait for without holding the worker.
    pub fn feed(&self) -> FrameFeed {
        FrameFeed(self.shared.clone())
    }
}

impl Drop for Worker {
    fn drop(&mut self) {
        self.shared.control.lock().map(|mut c| c.quit = true).ok();
        self.shared.wake.notify_all();
        if let Some(thread) = self.thread.take() {
            let _ = thread.join();
        }
    }
}

/// The GPU context and its compiled kernel, or why there is none.
type Gpu = Result<(GpuContext, TracePipeline), String>;

struct Renderer {
    world: World,
    gpu: Gpu,
    queue: Option<wgpu::Queue>,
    shared: Arc<Shared>,
    repaint: Box<dyn Fn() + Send>,
}

/// A view's accumulation on either backend.
enum View<'t> {
    Gpu {
        tracer: Box<GpuTracer<'t>>,
        progressive: Box<ProgressiveTrace>,
        per_step: u32,
        /// The texture a [`Target::Host`] is drawn into before it is read back, and the
        /// read-back's staging buffer, both kept between steps.
        host: Option<wgpu::Texture>,
        readback: splat_gpu::Rgba8Readback,
    },
    /// The CPU's running mean, and the algorithm prepared for the view (a splatting method's
    /// projected and sorted splats, kept while the camera holds still).
    Cpu(CpuAccumulation, Option<Box<PreparedView<'t>>>),
}

/// Frames per second over a sliding second.
struct Rate {
    since: Instant,
    frames: u32,
    value: f32,
}

impl Rate {
    fn new() -> Self {
        Self { since: Instant::now(), frames: 0, value: 0.0 }
    }

    fn add(&mut self, frames: u32) -> f32 {
        self.frames += frames;
        let elapsed = self.since.elapsed().as_secs_f32();
        if elapsed >= 0.5 {
            self.value = self.frames as f32 / elapsed;
            (self.since, self.frames) = (Instant::now(), 0);
        }
        self.value
    }
}

/// Why a view's loop ended.
enum Outcome {
    /// The window closed.
    Quit,
    /// The scene's settings changed: build the BVH again.
    Rebuild,
    /// The lighting changed: the same BVH, lit anew.
    Relight,
}

impl Renderer {
    fn run(self) {
        let Next::New(mut id, mut job) = self.shared.next(0, true) else { return };
        loop {
            let trace =
                TraceScene::new(&self.world.scene, job.settings.render).map(|t| t.with_meshes(&self.world.meshes));
            let outcome = match trace {
                Ok(mut trace) => loop {
                    let lit = trace.with_lighting(job.settings.lighting(&self.world.lighting));
                    match lit {
                        Ok(lit) => trace = lit,
                        Err(e) => break self.fail(&mut id, &mut job, e.to_string()),
                    }
                    match self.render(&trace, &mut id, &mut job) {
                        Outcome::Relight => continue,
                        other => break other,
                    }
                },
                Err(e) => self.fail(&mut id, &mut job, e.to_string()),
            };
            if let Outcome::Quit = outcome {
                return;
            }
        }
    }

    /// Report `error` for job `id` and wait for another job.
    fn fail(&self, id: &mut u64, job: &mut Box<Job>, error: String) -> Outcome {
        self.shared.publish(Status { job: *id, error: Some(error), idle: true, ..Status::default() });
        (self.repaint)();
        match self.shared.next(*id, true) {
            Next::New(new, next) => {
                (*id, *job) = (new, next);
                Outcome::Rebuild
            }
            _ => Outcome::Quit,
        }
    }

    /// Render views of `trace` until a job needs another scene or lighting, or the window
    /// closes.
    fn render(&self, trace: &TraceScene, id: &mut u64, job: &mut Box<Job>) -> Outcome {
        let mut view = match self.view(trace, job) {
            Ok(view) => view,
            Err(e) => return self.fail(id, job, e),
        };
        let mut status = Status { job: *id, ..Status::default() };
        let mut rate = Rate::new();
        let mut reference: Option<RenderOutput> = None;
        loop {
            let busy = !status.idle && status.error.is_none();
            match self.shared.next(*id, !busy) {
                Next::Quit => return Outcome::Quit,
                Next::New(new, next) => {
                    let rebuild = next.settings.scene_key() != job.settings.scene_key();
                    let relight = next.settings.lighting_key() != job.settings.lighting_key();
                    let restart = next.camera != job.camera
                        || next.generation != job.generation
                        || next.settings.frames_key() != job.settings.frames_key();
                    (*id, *job) = (new, next);
                    if rebuild {
                        return Outcome::Rebuild;
                    }
                    if relight {
                        return Outcome::Relight;
                    }
                    status.job = *id;
                    if restart {
                        reference = None;
                        rate = Rate::new();
                        status = Status { job: *id, ..Status::default() };
                        if let Err(e) = self.restart(&mut view, job) {
                            status.error = Some(e);
                        }
                    }
                }
                Next::Same => match self.step(&mut view, trace, job) {
                    Ok(frames) => {
                        status.frames = self.frames(&view);
                        status.frames_per_second = rate.add(frames);
                        if job.settings.rmse {
                            status.rmse =
                                self.rmse(&view, trace, job, &mut reference).map_err(|e| status.error = Some(e)).ok();
                        }
                    }
                    Err(e) => status.error = Some(e),
                },
            }
            if let Err(e) = self.present(&mut view, job, *id) {
                status.error = Some(e);
            }
            // Paused, a view still gets its first frame: a camera moved while paused shows
            // where it looks rather than a black texture.
            let paused = job.settings.paused && self.frames(&view) >= 1;
            status.idle = paused || self.finished(&view, trace, job);
            self.shared.publish(status.clone());
            (self.repaint)();
        }
    }

    /// A fresh view of `job` on the backend its settings name.
    fn view<'t>(&'t self, trace: &'t TraceScene<'t>, job: &Job) -> Result<View<'t>, String> {
        if !job.settings.on_gpu() {
            return Ok(View::Cpu(CpuAccumulation::new(job.camera.width, job.camera.height), None));
        }
        let (ctx, pipeline) = self.gpu.as_ref().map_err(|e| format!("the GPU tracer cannot run: {e}"))?;
        // The backend's rules, as the CLI asks them, before anything is uploaded.
        splat_gpu::supports(&job.settings.algorithm(), splat_gpu::Extras::default()).map_err(|e| e.to_string())?;
        let tracer = GpuTracer::new(ctx, pipeline, trace).map_err(|e| e.to_string())?;
        let progressive = ProgressiveTrace::new(&tracer, &job.camera, &job.settings.method(), &stream(&job.settings))
            .map_err(|e| e.to_string())?;
        Ok(View::Gpu {
            tracer: Box::new(tracer),
            progressive: Box::new(progressive),
            per_step: 1,
            host: None,
            readback: Default::default(),
        })
    }

    fn restart(&self, view: &mut View, job: &Job) -> Result<(), String> {
        match view {
            View::Gpu { tracer, progressive, per_step, .. } => {
                *per_step = 1;
                progressive.set_camera(tracer, &job.camera).map_err(|e| e.to_string())?;
                progressive.set_frames(&stream(&job.settings)).map_err(|e| e.to_string())?;
                progressive.set_method(&job.settings.method()).map_err(|e| e.to_string())
            }
            View::Cpu(acc, prepared) => {
                *acc = CpuAccumulation::new(job.camera.width, job.camera.height);
                *prepared = None;
                Ok(())
            }
        }
    }

    fn frames(&self, view: &View) -> u32 {
        match view {
            View::Gpu { progressive, .. } => progressive.frames(),
            View::Cpu(acc, _) => acc.frames(),
        }
    }

    /// Whether more frames would change nothing or the limit is reached.
    fn finished(&self, view: &View, trace: &TraceScene, job: &Job) -> bool {
        let deterministic = !(job.settings.algorithm().is_stochastic() || trace.is_random());
        let frames = self.frames(view);
        frames >= job.settings.max_frames || deterministic && frames >= 1
    }

    /// Fold more frames in: on the GPU as many as keep a step near 20 ms, on the CPU one.
    fn step<'t>(&self, view: &mut View<'t>, trace: &'t TraceScene<'t>, job: &Job) -> Result<u32, String> {
        let left = job.settings.max_frames.saturating_sub(self.frames(view));
        match view {
            View::Gpu { tracer, progressive, per_step, .. } => {
                let start = Instant::now();
                let done = progressive.step(tracer, (*per_step).min(left)).map_err(|e| e.to_string())?;
                let ctx = tracer.context();
                ctx.device.poll(wgpu::PollType::wait_indefinitely()).map_err(|e| e.to_string())?;
                let took = start.elapsed();
                if took < Duration::from_millis(10) {
                    *per_step = (*per_step * 2).min(splat_gpu::FRAMES_PER_DISPATCH);
                } else if took > Duration::from_millis(40) {
                    *per_step = (*per_step / 2).max(1);
                }
                Ok(done)
            }
            View::Cpu(acc, prepared) => {
                let view = match prepared {
                    Some(view) => view,
                    None => {
                        let view = job.settings.algorithm().prepare(trace, &job.camera).map_err(|e| e.to_string())?;
                        prepared.insert(Box::new(view))
                    }
                };
                let frame = view.render(&cpu_frame(&job.settings, acc.frames()), &|_| {});
                acc.fold(&frame.map_err(|e| e.to_string())?, job.settings.accumulation);
                Ok(1)
            }
        }
    }

    /// Draw what is accumulated into the job's target (job `id`).
    fn present(&self, view: &mut View, job: &Job, id: u64) -> Result<(), String> {
        let display = job.settings.display;
        let frames = self.frames(view);
        match (view, &job.target) {
            (View::Gpu { tracer, progressive, host, readback, .. }, target) => {
                let ctx = tracer.context();
                let texture = match target {
                    Target::Texture(texture) => texture,
                    Target::Host => host_texture(ctx, host, progressive.camera()),
                };
                let mut encoder = ctx.device.create_command_encoder(&Default::default());
                let view = texture.create_view(&Default::default());
                progressive.present(ctx, &mut encoder, &view, texture.format(), &display).map_err(|e| e.to_string())?;
                ctx.queue.submit([encoder.finish()]);
                if let Target::Host = target {
                    let rgba = readback.read(&ctx.device, &ctx.queue, texture).map_err(|e| e.to_string())?;
                    self.shared.publish_frame(id, frames, (texture.width(), texture.height()), rgba);
                }
            }
            (View::Cpu(acc, _), Target::Texture(texture)) => {
                let (w, h) = (texture.width(), texture.height());
                let queue = self.queue.as_ref().ok_or("no queue to upload the view with")?;
                if (w, h) == acc.size() {
                    queue.write_texture(
                        texture.as_image_copy(),
                        &acc.rgba8(&display),
                        wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(4 * w), rows_per_image: Some(h) },
                        texture.size(),
                    );
                }
            }
            (View::Cpu(acc, _), Target::Host) => self.shared.publish_frame(id, frames, acc.size(), acc.rgba8(&display)),
        }
        Ok(())
    }

    /// The RMSE of the running mean against the exact image of the view, rendered once per
    /// view on the same backend.
    fn rmse(
        &self,
        view: &View,
        trace: &TraceScene,
        job: &Job,
        reference: &mut Option<RenderOutput>,
    ) -> Result<f64, String> {
        let exact = Frames::default();
        let (mean, reference) = match view {
            View::Gpu { tracer, progressive, .. } => {
                if reference.is_none() {
                    *reference = Some(tracer.render(&job.camera, &Method::Exact, &exact).map_err(|e| e.to_string())?.0);
                }
                (progressive.read(tracer.context()).map_err(|e| e.to_string())?.mean, reference.as_ref())
            }
            View::Cpu(acc, _) => {
                if reference.is_none() {
                    let render = Algorithm::Trace(Method::Exact).render_on(trace, &job.camera, &exact, &|_| {});
                    *reference = Some(render.map_err(|e| e.to_string())?);
                }
                (acc.mean_image(), reference.as_ref())
            }
        };
        Ok(splat_core::stats::rmse(mean.data(), reference.expect("set above").mean.data()))
    }
}

/// A `width` × `height` texture of [`TEXTURE_FORMAT`] the display pass draws a view into, with
/// `usage` besides (the window samples it, the host view copies it out).
pub fn view_texture(device: &wgpu::Device, (width, height): (u32, u32), usage: wgpu::TextureUsages) -> wgpu::Texture {
    device.create_texture(&wgpu::TextureDescriptor {
        label: Some("splat view"),
        size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D2,
        format: TEXTURE_FORMAT,
        usage: wgpu::TextureUsages::RENDER_ATTACHMENT | usage,
        view_formats: &[],
    })
}

/// The texture a [`Target::Host`] view of `camera` is drawn into on the device, made again
/// when the size changes.
fn host_texture<'a>(ctx: &GpuContext, host: &'a mut Option<wgpu::Texture>, camera: &Camera) -> &'a wgpu::Texture {
    let size = (camera.width, camera.height);
    if host.as_ref().is_some_and(|t| (t.width(), t.height()) != size) {
        *host = None;
    }
    host.get_or_insert_with(|| view_texture(&ctx.device, size, wgpu::TextureUsages::COPY_SRC))
}

/// The random stream of a job: the GPU view draws frame i with key i of the panel's seed, as
/// a batch render of that seed does.
fn stream(settings: &Settings) -> Frames {
    Frames {
        count: 1,
        first: 0,
        seed: settings.seed,
        rng: settings.rng,
        u_shift: 0.0,
        accumulation: settings.accumulation,
    }
}

/// Frame `i` of a job on the CPU: frame `i` of a batch render of the panel's seed (its key
/// and its camera sample), as a share of a run renders it, so that the view after n frames
/// shows the frames of `splat render` with n frames.
fn cpu_frame(settings: &Settings, i: u32) -> Frames {
    // One frame at full precision: the view's accumulation stores the running mean.
    let accumulation = splat_core::frame::AccumulationFormat::F32;
    Frames { first: i, accumulation, ..stream(settings) }
}
