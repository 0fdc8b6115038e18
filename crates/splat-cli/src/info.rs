//! `splat info`: what is in a scene file, or in a world (a world file, a glTF file's meshes).

use anyhow::Result;
use clap::Args;
use std::path::PathBuf;

/// Arguments of `splat info`.
#[derive(Args)]
pub struct InfoArgs {
    /// Scene file: any format `splat render` reads; a world file (.toml) or a glTF file's
    /// meshes are listed with their materials.
    pub scene: PathBuf,
    /// The capture's cameras (a cameras.json, COLMAP model or transforms.json): `info` then
    /// says which way is up, the mean up of the views, as an `--up` for framing; and for a
    /// COLMAP model with its points3D, which world the splats lie in (the model's own, or
    /// gsplat's normalised world, which --gsplat-world renders).
    #[arg(long)]
    pub camera: Option<PathBuf>,
    /// A Nerfstudio training run's dataparser_transforms.json: moves the cameras of a
    /// transforms.json (--camera) into the run's normalised world, where splatfacto's exported
    /// splats (ns-export gaussian-splat) live.
    #[arg(long, requires = "camera")]
    pub dataparser_transforms: Option<PathBuf>,
    /// A 4 × 4 (or 3 × 4) matrix [s R | t] from the world of --camera to the splats' world, as
    /// `splat render --world-transform` takes it: the views are moved by it, and for a COLMAP
    /// model `info` says how many of its 3D points it puts on the splats.
    #[arg(
        long,
        value_name = "FILE",
        requires = "camera",
        conflicts_with = "dataparser_transforms",
        value_parser = splat_view::world_transform_parser
    )]
    pub world_transform: Option<splat_io::similarity::Similarity>,
    /// How scene files are read.
    #[command(flatten)]
    pub read: crate::args::ReadArgs,
}

/// Run `splat info`.
pub fn run(args: InfoArgs) -> Result<()> {
    let mut text = String::new();
    macro_rules! out {
        ($($arg:tt)*) => {{
            use std::fmt::Write as _;
            let _ = writeln!(text, $($arg)*);
        }};
    }
    // A world file, or a glTF file that may hold meshes: its meshes (and, for a world file,
    // all it holds) from the world reader; the splats of a glTF file as any scene file's.
    let gltf = matches!(splat_io::extension(&args.scene).as_deref(), Some("glb" | "gltf"));
    let world = if splat_io::world::is_world_file(&args.scene) || gltf {
        let opened = splat_io::world::open_world(Some(&args.scene), args.read.options())?;
        crate::args::print_notes(&args.scene, &opened.notes);
        if !gltf || opened.world.scene.particles.is_empty() {
            out!("file       {}", args.scene.display());
            return print(&(text + &world_text(&opened.world)));
        }
        Some(opened.world)
    } else {
        None
    };
    let started = std::time::Instant::now();
    let read = crate::args::read_scene(&args.scene, args.read)?;
    let seconds = started.elapsed().as_secs_f64();
    let scene = read.scene;
    let n = scene.particles.len();
    out!("file       {}", args.scene.display());
    if read.detail.is_empty() {
        out!("format     {}", read.format.name());
    } else {
        out!("format     {} ({})", read.format.name(), read.detail);
    }
    out!("particles  {n}");
    out!("SH degree  {}", scene.sh_degree);
    // The rate of a read of one file (a SOG folder's meta.json is not all it read).
    let one_file =
        !(read.format == splat_io::SceneFormat::Sog && splat_io::extension(&args.scene).as_deref() != Some("sog"));
    let file_bytes = std::fs::metadata(&args.scene).ok().filter(|m| m.is_file() && one_file).map(|m| m.len());
    let mb = |bytes: f64| bytes / 1e6;
    match file_bytes {
        Some(bytes) => {
            out!("read       {seconds:.2} s, {:.0} MB/s ({:.1} MB)", mb(bytes as f64) / seconds, mb(bytes as f64))
        }
        None => out!("read       {seconds:.2} s"),
    }
    let held = scene.heap_bytes() as f64;
    let per_splat = held / n.max(1) as f64;
    let ratio = file_bytes.map_or(String::new(), |f| format!(", {:.2} × the file", held / f as f64));
    let peak = splat_io::memory::peak_resident()
        .map_or(String::new(), |p| format!("; the process's peak {:.1} MB", mb(p as f64)));
    out!("memory     {:.1} MB held, {per_splat:.0} bytes a splat{ratio}{peak}", mb(held));
    if read.filter_3d {
        out!("3D filter  Mip-Splatting's filter_3D, applied (scales and opacities as Mip-Splatting renders them)");
    }
    if read.surfels {
        out!(
            "surfels    2D Gaussians (2DGS), read as Gaussians {:.0e} × their larger scale thick: the ray tracers \
             and splatting (--response along-ray, its default for them) evaluate them at their ray–splat intersection",
            splat_core::particle::SURFEL_THICKNESS
        );
    }
    if let Some(preset) = args.read.preset {
        out!(
            "preset     {} (kernel degree {}, cutoff {:.4}σ, extent {}, response {})",
            preset.describe(),
            preset.kernel_degree(),
            preset.cutoff(),
            preset.extent().name(),
            preset.response().name()
        );
    }
    if let Some(trained) = scene.trained {
        let chosen = if args.read.preset.is_some() { "; --preset chooses another" } else { "" };
        let (extent, response) = splat_core::trainer::capture_splatting(&scene);
        out!(
            "trained    through {} (extent {}, response {}), as its file or run says{chosen}",
            trained.describe(),
            extent.name(),
            response.name()
        );
    }
    let filter = scene.screen_filter;
    if filter == read.file_filter {
        out!("2D filter  {}", filter.describe());
    } else {
        out!(
            "2D filter  {} (by --screen-filter or --preset; the file names {})",
            filter.describe(),
            read.file_filter.name()
        );
    }
    if let Some(world) = &world {
        text += &world_text(world);
    }
    if n == 0 {
        return print(&text);
    }
    let b = scene.mean_bounds();
    let r = scene.robust_bounds(0.01);
    out!("bounds     min {:.3} max {:.3}", b.min, b.max);
    out!("1–99 %     min {:.3} max {:.3}", r.min, r.max);
    let (lo, hi) = scene
        .particles
        .iter()
        .fold((f32::INFINITY, 0.0f32), |(lo, hi), p| (lo.min(p.scale.min_element()), hi.max(p.scale.max_element())));
    out!("scale      {lo:.2e} … {hi:.2e}");
    let options = splat_io::cameras::ViewOptions {
        dataparser: args.dataparser_transforms.as_deref(),
        world_transform: args.world_transform,
        ..Default::default()
    };
    out!("{}", camera_lines(args.camera.as_deref(), options, &scene)?);
    out!("opacity histogram:");
    let mut bins = [0usize; 10];
    for p in &scene.particles {
        bins[((p.opacity * 10.0) as usize).min(9)] += 1;
    }
    let max = *bins.iter().max().unwrap_or(&1);
    for (i, &count) in bins.iter().enumerate() {
        let bar = "#".repeat((40 * count).div_ceil(max.max(1)));
        out!(
            "  [{:.1}, {:.1}{} {count:>9}  {bar}",
            i as f32 / 10.0,
            (i + 1) as f32 / 10.0,
            if i == 9 { "]" } else { ")" }
        );
    }
    print(&text)
}

/// What a world holds besides a scene file's statistics: its sets, lights and camera, and each
/// mesh with its triangles and material.
fn world_text(world: &splat_io::world::WorldSpec) -> String {
    use std::fmt::Write as _;
    let mut text = String::new();
    let triangles: usize = world.meshes.iter().map(|(m, _)| m.triangles.len()).sum();
    let (sets, lights) = (world.lighting.sets.len(), world.lighting.lights.len());
    let splats = match world.scene.particles.len() {
        0 => "no splats".to_string(),
        n => format!(
            "{} of {} (SH degree {})",
            crate::counted(sets, "splat set"),
            crate::counted(n, "particle"),
            world.scene.sh_degree
        ),
    };
    let meshes = match world.meshes.len() {
        1 => "1 mesh".to_string(),
        n => format!("{n} meshes"),
    };
    let _ = writeln!(
        text,
        "world      {splats}, {}, {meshes} ({})",
        crate::counted(lights, "light"),
        crate::counted(triangles, "triangle")
    );
    if let Some(c) = &world.camera {
        let (eye, ahead) = (c.center(), c.forward());
        let _ = writeln!(text, "camera     eye {eye:.3}, looking along {ahead:.3}, {}×{}", c.width, c.height);
    }
    for (i, (mesh, m)) in world.meshes.iter().enumerate() {
        let _ = writeln!(
            text,
            "mesh {i:<5} {}: colour {:.3}, mirror {} (tint {:.3}), transmission {} (ior {}), roughness {}, specular layer {}, opacity {}, emission {:.3}",
            crate::counted(mesh.triangles.len(), "triangle"),
            m.color,
            m.mirror,
            m.mirror_tint,
            m.transmission,
            m.ior,
            m.roughness,
            m.specular_layer,
            m.opacity,
            m.shading.emissive * m.color,
        );
    }
    text
}

/// What the capture's views say: which way is up (the mean up of the views when `cameras` are
/// given, otherwise what trained captures usually use), their lenses, and for a COLMAP model
/// which world the splats of `scene` lie in.
fn camera_lines(
    cameras: Option<&std::path::Path>,
    options: splat_io::cameras::ViewOptions,
    scene: &splat_core::Scene,
) -> Result<String> {
    let Some(path) = cameras else {
        return Ok("up         not measured (no --camera): captures trained from COLMAP data are usually \
                   -y up; frame them with --up 0,-1,0"
            .into());
    };
    let views: Vec<_> = crate::args::load_cameras(path, options)?.into_iter().map(|(_, c)| c).collect();
    let world = world_line(path, options.world_transform, scene).map_or(String::new(), |line| format!("\n{line}"));
    Ok(format!("{}\n{}{world}", up_line(&views), lens_line(&views)))
}

/// For a COLMAP model, which world the splats lie in: the model's own, or gsplat's normalised
/// world (rendered with --gsplat-world), by the share of its 3D points on the splats in each;
/// with a `world_transform`, the share it puts there.
fn world_line(
    path: &std::path::Path,
    world_transform: Option<splat_io::similarity::Similarity>,
    scene: &splat_core::Scene,
) -> Option<String> {
    use splat_io::gsplat_world::{normalized_world, on_splats_in, on_splats_in_colmap};
    if !splat_io::colmap::is_colmap(path) {
        return None;
    }
    let measured = || -> Result<String, String> {
        let points = splat_io::colmap::read_points3d(path).map_err(|e| e.to_string())?;
        let posed = splat_io::colmap::read_colmap_posed(path).map_err(|e| e.to_string())?;
        let poses: Vec<_> = posed.iter().map(splat_io::colmap::PosedView::pose).collect();
        let means: Vec<_> = scene.particles.iter().map(|p| p.mean).collect();
        let colmap = on_splats_in_colmap(&poses, &points, &means)?;
        let percent = |f: f64| format!("{:.0} %", 100.0 * f);
        if let Some(world) = world_transform {
            let moved = on_splats_in(world, &poses, &points, &means)?;
            return Ok(format!(
                "--world-transform's: {} of the model's 3D points lie on the splats there, {} in the model's own",
                percent(moved),
                percent(colmap)
            ));
        }
        let gsplat = normalized_world(&poses, &points, &means);
        Ok(match gsplat {
            Ok((world, g)) if g > colmap => {
                // The views' mean up, moved into gsplat's world: what frames the splats there.
                let up: glam::DVec3 = poses.iter().map(|(r, _)| -(world.rotation * r.y_axis)).sum();
                format!(
                    "gsplat's normalised world ({} of the model's 3D points lie on the splats there, {} in the \
                     model's own): render with --gsplat-world; without cameras, frame with --up {}",
                    percent(g),
                    percent(colmap),
                    up_flag(up.as_vec3())
                )
            }
            _ if colmap >= splat_io::gsplat_world::FEW => {
                format!("the COLMAP model's own ({} of its 3D points lie on the splats)", percent(colmap))
            }
            Ok((_, g)) => format!(
                "unclear: {} of the model's 3D points lie on the splats in its own world, {} in gsplat's",
                percent(colmap),
                percent(g)
            ),
            Err(why) => format!(
                "unclear: {} of the model's 3D points lie on the splats in its own world; gsplat's: {why}",
                percent(colmap)
            ),
        })
    };
    Some(match measured() {
        Ok(world) => format!("world      {world}"),
        Err(why) => format!("world      not measured: {why}"),
    })
}

/// The views' lenses, counted; where some are distorted, that the trainers which undistort their
/// photos trained on pinholes, and how to render those.
fn lens_line(views: &[splat_core::Camera]) -> String {
    let mut counts: Vec<(&str, usize)> = Vec::new();
    for view in views {
        let lens = view.lens.describe();
        match counts.iter_mut().find(|(name, _)| *name == lens) {
            Some((_, n)) => *n += 1,
            None => counts.push((lens, 1)),
        }
    }
    let list: Vec<String> = counts.iter().map(|(lens, n)| format!("{lens} ({})", crate::counted(*n, "view"))).collect();
    let distorted = views.iter().any(|v| v.lens.distortion().is_some_and(|d| *d != Default::default()));
    let advice = "\n           splatfacto and gsplat train on these photographs undistorted: --undistort \
                  splatfacto or --undistort gsplat renders their pinholes";
    format!("lenses     {}{}", list.join(", "), if distorted { advice } else { "" })
}

/// Which way is up: the mean up of `views`.
fn up_line(views: &[splat_core::Camera]) -> String {
    match splat_core::Camera::mean_up(views) {
        Some(up) => format!(
            "up         {:.2},{:.2},{:.2}, the mean of {}: frame with --up {}",
            up.x,
            up.y,
            up.z,
            crate::counted(views.len(), "view"),
            up_flag(up)
        ),
        None => format!("up         the {} views disagree (no common up)", views.len()),
    }
}

/// The axis nearest `up`, as --up takes it ("0,-1,0").
fn up_flag(up: glam::Vec3) -> String {
    let axis = up.abs().max_position();
    let sign = if up[axis] < 0.0 { "-" } else { "" };
    let mut flag = [0; 3].map(|z: i32| z.to_string());
    flag[axis] = format!("{sign}1");
    flag.join(",")
}

/// Write `text` to stdout; a closed pipe (`splat info … | head`) is not an error.
fn print(text: &str) -> Result<()> {
    use std::io::Write as _;
    match std::io::stdout().lock().write_all(text.as_bytes()) {
        Err(e) if e.kind() == std::io::ErrorKind::BrokenPipe => Ok(()),
        result => Ok(result?),
    }
}
