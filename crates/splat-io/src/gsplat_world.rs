//! gsplat's normalised world: where the splats of its `simple_trainer` live by default.
//!
//! gsplat's COLMAP parser (`examples/datasets/colmap.py`, `Parser(normalize=True)`, which
//! `simple_trainer` runs with its default `normalize_world_space=True`) moves the capture before
//! training, by three transforms (`examples/datasets/normalize.py`):
//!
//! 1. **T₁ = `similarity_from_cameras`**, a similarity:
//!    - a rotation taking the cameras' mean up (their −y axis) onto −y in the world;
//!    - a translation putting at the origin the median of the points nearest the origin on
//!      the cameras' optical axes;
//!    - a scale making the median camera distance from there 1.
//! 2. **T₂ = `align_principal_axes`** of the 3D points (`points3D`, as float32): their
//!    median goes to the origin, and the rotation's rows are the eigenvectors of their
//!    covariance, largest eigenvalue first. So x is the points' longest axis and z their
//!    thinnest.
//! 3. **T₃ = a half turn about x**, where the points' median z is above their mean z (the
//!    ground is assumed to be below).
//!
//! The run saves none of this, and its exported splats (`save_ply`) are in the world
//! T₃ T₂ T₁ makes. To render them, the COLMAP model's cameras must be moved there.
//!
//! Steps 1 and 3 are deterministic. Step 2's eigenvectors come from `numpy.linalg.eigh`, whose
//! signs are LAPACK's. gsplat makes the determinant positive, and step 3 then fixes the z axis
//! by the data; so two frames remain, a half turn about z apart. [`normalized_world`] keeps the
//! one that puts the model's 3D points on the splats, and refuses a capture where that does
//! not tell them apart.

use crate::similarity::{Pose, Similarity};
use glam::{DMat3, DVec3, Vec3};

/// Side of the cells in which one of the model's 3D points looks for a splat, in the normalised
/// world (where the median camera is 1 from the scene's centre).
const CELL: f64 = 0.01;

/// How much more often the chosen frame alone must put a point on the splats than the other
/// frame alone does.
const ODDS: f64 = 3.0;

/// The least share of the points that the chosen frame alone must put on the splats, beyond
/// those the other frame alone puts there.
const EXCESS: f64 = 0.05;

/// Below this share of a model's 3D points on the splats, splats are not taken to lie in a world.
pub const FEW: f64 = 0.25;

/// The similarity taking a COLMAP model's world (its cameras' `poses`, its 3D `points`) to
/// gsplat's normalised world, where splats with these `means` were trained: of the two
/// [`frames`] gsplat's normalisation can give, the one that puts the points on the splats; with
/// the share of the points on the splats there.
///
/// The decision rests on the points the two frames disagree on: a point on the splats in one
/// frame and off them in the other. The frame with more of them is taken where it has at
/// least `ODDS` (3) times as many as the other, and they exceed the other's by `EXCESS` (5 %)
/// of all points; points on the splats in both frames (a level ground, a round table) say nothing.
pub fn normalized_world(poses: &[Pose], points: &[DVec3], means: &[Vec3]) -> Result<(Similarity, f64), String> {
    let frames = frames(poses, points)?;
    let occupied = Occupancy::of(means, CELL);
    let [on_a, on_b] = frames.map(|frame| points.iter().map(|&p| occupied.near(frame.point(p))).collect::<Vec<_>>());
    let only = |x: &[bool], y: &[bool]| x.iter().zip(y).filter(|&(&x, &y)| x && !y).count() as f64;
    let (a, b) = (only(&on_a, &on_b), only(&on_b, &on_a));
    let n = points.len() as f64;
    let share = |on: &[bool]| on.iter().filter(|&&on| on).count() as f64 / n;
    let (on_a, on_b) = (share(&on_a), share(&on_b));
    let (chosen, on_chosen, mine, theirs) = if a >= b { (frames[0], on_a, a, b) } else { (frames[1], on_b, b, a) };
    if mine >= ODDS * theirs && mine - theirs >= EXCESS * n {
        return Ok((chosen, on_chosen));
    }
    let percent = |f: f64| format!("{:.0} %", 100.0 * f);
    let on_colmap = on_splats(&Occupancy::of(means, CELL / chosen.scale), points);
    let why = if on_colmap >= FEW && on_colmap > on_a.max(on_b) {
        format!(
            "the splats lie in the COLMAP model's own world ({} of its 3D points are on them there, {} and {} in the \
             two frames of gsplat's), not in gsplat's normalised world: they were trained without \
             normalize_world_space, or by another trainer",
            percent(on_colmap),
            percent(on_a),
            percent(on_b)
        )
    } else if on_a.max(on_b) < FEW {
        format!(
            "few of the model's 3D points lie on the splats in either frame gsplat's normalisation can give ({} and \
             {}): the splats are not of this capture, or not gsplat's",
            percent(on_a),
            percent(on_b)
        )
    } else {
        format!(
            "the capture looks alike under a half turn about its up axis: {} and {} of the model's 3D points lie on \
             the splats in the two frames numpy's eigenvector signs can give, too close to tell which gsplat took",
            percent(on_a),
            percent(on_b)
        )
    };
    Err(why)
}

/// The share of a COLMAP model's 3D `points` on splats with these `means` where both are in the
/// model's own world, by the measure [`normalized_world`] takes in gsplat's (cells 1 % of the
/// median camera distance).
pub fn on_splats_in_colmap(poses: &[Pose], points: &[DVec3], means: &[Vec3]) -> Result<f64, String> {
    on_splats_in(Similarity::IDENTITY, poses, points, means)
}

/// [`on_splats_in_colmap`] where `world` moves the model (its cameras' `poses`, its 3D `points`)
/// into the splats' world.
pub fn on_splats_in(world: Similarity, poses: &[Pose], points: &[DVec3], means: &[Vec3]) -> Result<f64, String> {
    let moved: Vec<Pose> = poses.iter().map(|&pose| world.pose(pose)).collect();
    let scale = similarity_from_cameras(&moved)?.scale;
    let points: Vec<DVec3> = points.iter().map(|&p| world.point(p)).collect();
    Ok(on_splats(&Occupancy::of(means, CELL / scale), &points))
}

/// The share of `points` near a splat of `occupied`.
fn on_splats(occupied: &Occupancy, points: &[DVec3]) -> f64 {
    points.iter().filter(|&&p| occupied.near(p)).count() as f64 / points.len().max(1) as f64
}

/// The two frames gsplat's normalisation T₃ T₂ T₁ can give a capture (module docs): with this
/// eigensolver's signs, and that after a half turn about z.
pub fn frames(poses: &[Pose], points: &[DVec3]) -> Result<[Similarity; 2], String> {
    // gsplat's parser reads the points as float32.
    let points: Vec<DVec3> = points.iter().map(|p| p.as_vec3().as_dvec3()).collect();
    if points.len() < 4 {
        return Err(format!(
            "the model has {} 3D points (points3D), and gsplat aligns its world with their principal axes",
            points.len()
        ));
    }
    let t1 = similarity_from_cameras(poses)?;
    let moved: Vec<DVec3> = points.iter().map(|&p| t1.point(p)).collect();
    let t2 = align_principal_axes(&moved)?;
    let mut world = t1.then(t2);
    let heights: Vec<f64> = points.iter().map(|&p| world.point(p).z).collect();
    if median(heights.clone()) > mean(&heights) {
        world = world.then(Similarity::rotation(DMat3::from_diagonal(DVec3::new(1.0, -1.0, -1.0))));
    }
    Ok([world, world.then(Similarity::rotation(DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0))))])
}

/// gsplat's `similarity_from_cameras(c2w)` with its defaults (`center_method="focus"`, median
/// scaling).
pub fn similarity_from_cameras(poses: &[Pose]) -> Result<Similarity, String> {
    if poses.is_empty() {
        return Err("the model has no camera".into());
    }
    let n = poses.len() as f64;
    let up_sum: DVec3 = poses.iter().map(|(r, _)| -r.y_axis).sum();
    let world_up = (up_sum / n).normalize_or_zero();
    if world_up == DVec3::ZERO {
        return Err("the cameras' up directions cancel out, so gsplat's normalisation has no up".into());
    }
    let up_camspace = DVec3::NEG_Y;
    let c = up_camspace.dot(world_up);
    let cross = world_up.cross(up_camspace);
    let skew = DMat3::from_cols(
        DVec3::new(0.0, cross.z, -cross.y),
        DVec3::new(-cross.z, 0.0, cross.x),
        DVec3::new(cross.y, -cross.x, 0.0),
    );
    // Rodrigues' rotation taking world_up onto up_camspace; where they are opposite, gsplat's
    // own choice (a mirror of x, which its comment calls a half turn about x).
    let r_align = if c > -1.0 {
        DMat3::IDENTITY + skew + skew * skew * (1.0 / (1.0 + c))
    } else {
        DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0))
    };
    // The point nearest the origin on each optical axis (the axes after the rotation).
    let nearest = |(r, t): &Pose| {
        let (forward, t) = (r_align * r.z_axis, r_align * *t);
        t + forward.dot(-t) * forward
    };
    let nearest: Vec<DVec3> = poses.iter().map(nearest).collect();
    let translate = -DVec3::new(
        median(nearest.iter().map(|p| p.x).collect()),
        median(nearest.iter().map(|p| p.y).collect()),
        median(nearest.iter().map(|p| p.z).collect()),
    );
    let distance = median(poses.iter().map(|(_, t)| (r_align * *t + translate).length()).collect());
    if !(distance > 0.0 && distance.is_finite()) {
        return Err(format!(
            "the median camera lies {distance} from the scene's centre, so gsplat's scale is undefined"
        ));
    }
    let scale = 1.0 / distance;
    Ok(Similarity { scale, rotation: r_align, translation: scale * translate })
}

/// gsplat's `align_principal_axes(points)`: the median to the origin, the covariance's
/// eigenvectors as the rotation's rows (largest eigenvalue first), the determinant made
/// positive by negating the first. The signs are this eigensolver's, not numpy's (module docs).
pub fn align_principal_axes(points: &[DVec3]) -> Result<Similarity, String> {
    let centroid = DVec3::new(
        median(points.iter().map(|p| p.x).collect()),
        median(points.iter().map(|p| p.y).collect()),
        median(points.iter().map(|p| p.z).collect()),
    );
    let (values, vectors) = symmetric_eigen(covariance(points.iter().map(|&p| p - centroid)));
    let mut order = [0, 1, 2];
    order.sort_by(|&i, &j| values[j].total_cmp(&values[i]));
    let [l1, l2, l3] = order.map(|i| values[i]);
    if !(l1 - l2 > 1e-9 * l1 && l2 - l3 > 1e-9 * l1) {
        return Err(format!(
            "the 3D points spread alike along two axes (covariance eigenvalues {l1:e}, {l2:e}, {l3:e}), so the axes \
             gsplat aligns the world with are numpy's arbitrary choice"
        ));
    }
    let mut axes = order.map(|i| vectors.col(i));
    if DMat3::from_cols(axes[0], axes[1], axes[2]).determinant() < 0.0 {
        axes[0] = -axes[0];
    }
    let rotation = DMat3::from_cols(axes[0], axes[1], axes[2]).transpose();
    Ok(Similarity { scale: 1.0, rotation, translation: -(rotation * centroid) })
}

/// numpy's `cov(x, rowvar=False)`: Σ (x − x̄)(x − x̄)ᵀ / (n − 1).
fn covariance(points: impl Iterator<Item = DVec3> + Clone) -> DMat3 {
    let n = points.clone().count() as f64;
    let mean = points.clone().sum::<DVec3>() / n;
    let outer = |d: DVec3| DMat3::from_cols(d * d.x, d * d.y, d * d.z);
    points.map(|p| outer(p - mean)).fold(DMat3::ZERO, |a, b| a + b) * (1.0 / (n - 1.0))
}

/// Eigenvalues and unit eigenvectors (the columns) of a symmetric matrix, by cyclic Jacobi
/// rotations (Golub & Van Loan §8.5): each rotation J zeroes one off-diagonal entry of Jᵀ A J.
fn symmetric_eigen(mut a: DMat3) -> (DVec3, DMat3) {
    let mut v = DMat3::IDENTITY;
    let off = |a: &DMat3| a.x_axis.y.powi(2) + a.x_axis.z.powi(2) + a.y_axis.z.powi(2);
    let scale = a.to_cols_array().iter().map(|e| e * e).sum::<f64>();
    for _sweep in 0..32 {
        if off(&a) <= 1e-32 * scale {
            break;
        }
        for (p, q) in [(0, 1), (0, 2), (1, 2)] {
            let apq = a.col(q)[p];
            if apq == 0.0 {
                continue;
            }
            // t = tan θ, the smaller root of t² + 2 τ t − 1 = 0, τ = (a_qq − a_pp) / 2 a_pq.
            let tau = (a.col(q)[q] - a.col(p)[p]) / (2.0 * apq);
            let t = tau.signum() / (tau.abs() + tau.hypot(1.0));
            let c = 1.0 / t.hypot(1.0);
            let mut j = DMat3::IDENTITY;
            j.col_mut(p)[p] = c;
            j.col_mut(q)[q] = c;
            j.col_mut(q)[p] = t * c;
            j.col_mut(p)[q] = -t * c;
            a = j.transpose() * a * j;
            v *= j;
        }
    }
    (DVec3::new(a.x_axis.x, a.y_axis.y, a.z_axis.z), v)
}

/// numpy's median: the middle value, or the mean of the two middle values.
fn median(mut values: Vec<f64>) -> f64 {
    values.sort_by(f64::total_cmp);
    let n = values.len();
    match n {
        0 => f64::NAN,
        _ if n % 2 == 1 => values[n / 2],
        _ => (values[n / 2 - 1] + values[n / 2]) / 2.0,
    }
}

fn mean(values: &[f64]) -> f64 {
    values.iter().sum::<f64>() / values.len() as f64
}

/// The cells of a grid that hold at least one splat's mean.
struct Occupancy {
    /// Side of a cell.
    cell: f64,
    /// The occupied cells' keys, sorted.
    keys: Vec<u64>,
}

/// Cells per axis on either side of the origin that [`Occupancy`] indexes.
const REACH: i64 = 1 << 20;

impl Occupancy {
    fn of(means: &[Vec3], cell: f64) -> Self {
        let mut keys: Vec<u64> = means.iter().filter_map(|m| key((m.as_dvec3() / cell).floor())).collect();
        keys.sort_unstable();
        keys.dedup();
        Self { cell, keys }
    }

    /// Whether a splat's mean lies in one of the 8 cells nearest `p` (every mean within half a
    /// cell of it along each axis does).
    fn near(&self, p: DVec3) -> bool {
        let low = (p / self.cell - 0.5).floor();
        (0..8).any(|corner| {
            let offset = DVec3::new((corner & 1) as f64, ((corner >> 1) & 1) as f64, (corner >> 2) as f64);
            key(low + offset).is_some_and(|k| self.keys.binary_search(&k).is_ok())
        })
    }
}

/// The key of the cell at integer coordinates `cell`, if it is within [`REACH`].
fn key(cell: DVec3) -> Option<u64> {
    let index = |x: f64| (x.abs() < REACH as f64).then(|| (x as i64 + REACH) as u64);
    Some((index(cell.x)? << 42) | (index(cell.y)? << 21) | index(cell.z)?)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn random(seed: &mut u64) -> f64 {
        *seed = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        (*seed >> 11) as f64 / (1u64 << 53) as f64
    }

    #[test]
    fn the_eigenvectors_diagonalise_a_symmetric_matrix() {
        let mut seed = 7;
        for _ in 0..200 {
            let m = DMat3::from_cols_array(&std::array::from_fn(|_| random(&mut seed) * 2.0 - 1.0));
            let a = m * m.transpose();
            let (values, v) = symmetric_eigen(a);
            let d = v.transpose() * a * v;
            assert!((v.transpose() * v - DMat3::IDENTITY).abs().to_cols_array().iter().all(|e| *e < 1e-14));
            for i in 0..3 {
                for j in 0..3 {
                    let expected = if i == j { values[i] } else { 0.0 };
                    assert!((d.col(j)[i] - expected).abs() < 1e-14, "{d:?}");
                }
            }
        }
    }

    /// Cameras on a circle about the origin, 4 above a ground, looking at the origin, COLMAP's
    /// way (y down, so the ground is at y = 1).
    fn circle_of_cameras() -> Vec<Pose> {
        (0..24)
            .map(|i| {
                let angle = i as f64 * std::f64::consts::TAU / 24.0;
                let centre = DVec3::new(4.0 * angle.cos(), -1.5, 4.0 * angle.sin());
                let forward = (-centre).normalize();
                let right = DVec3::Y.cross(forward).normalize();
                (DMat3::from_cols(right, forward.cross(right), forward), centre)
            })
            .collect()
    }

    /// A 4 × 2 patch of ground and, where `lopsided`, a box standing on it off the centre.
    fn capture(lopsided: bool, seed: &mut u64) -> Vec<DVec3> {
        let mut points: Vec<DVec3> =
            (0..4000).map(|_| DVec3::new(4.0 * random(seed) - 2.0, 1.0, 2.0 * random(seed) - 1.0)).collect();
        if lopsided {
            let corner = DVec3::new(0.6, 0.2, 0.1);
            points.extend((0..3000).map(|_| corner + 0.8 * DVec3::new(random(seed), random(seed), random(seed))));
        }
        points
    }

    /// Splats where `frame` puts the points, moved by up to a hundredth of a cell.
    fn splats(frame: &Similarity, points: &[DVec3], seed: &mut u64) -> Vec<Vec3> {
        let jitter = |seed: &mut u64| 1e-4 * (DVec3::new(random(seed), random(seed), random(seed)) - 0.5);
        points.iter().map(|&p| (frame.point(p) + jitter(seed)).as_vec3()).collect()
    }

    #[test]
    fn the_frame_whose_points_lie_on_the_splats_is_chosen() {
        let mut seed = 11;
        let (poses, points) = (circle_of_cameras(), capture(true, &mut seed));
        let frames = frames(&poses, &points).unwrap();
        for frame in frames {
            let (chosen, on_splats) = normalized_world(&poses, &points, &splats(&frame, &points, &mut seed)).unwrap();
            assert_eq!(chosen, frame);
            assert_eq!(on_splats, 1.0);
        }
        // The two frames are a half turn about z apart.
        let half_turn = frames[1].rotation * frames[0].rotation.transpose();
        assert!(half_turn.abs_diff_eq(DMat3::from_diagonal(DVec3::new(-1.0, -1.0, 1.0)), 1e-12));
    }

    #[test]
    fn a_capture_alike_under_a_half_turn_or_splats_elsewhere_are_refused() {
        let mut seed = 5;
        let poses = circle_of_cameras();
        let symmetric = capture(false, &mut seed);
        let frame = frames(&poses, &symmetric).unwrap()[0];
        let e = normalized_world(&poses, &symmetric, &splats(&frame, &symmetric, &mut seed)).unwrap_err();
        assert!(e.contains("looks alike under a half turn"), "{e}");
        let points = capture(true, &mut seed);
        let colmap = Similarity::rotation(DMat3::IDENTITY);
        let e = normalized_world(&poses, &points, &splats(&colmap, &points, &mut seed)).unwrap_err();
        assert!(e.contains("COLMAP model's own world"), "{e}");
        let elsewhere = Similarity { translation: DVec3::splat(5.0), ..frames(&poses, &points).unwrap()[0] };
        let e = normalized_world(&poses, &points, &splats(&elsewhere, &points, &mut seed)).unwrap_err();
        assert!(e.contains("not of this capture"), "{e}");
    }

    #[test]
    fn a_median_is_numpys() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
    }
}
