//! The catalogue of rendering methods: every method the project renders, declared once with its
//! name, its parameters (defaults and limits), whether it draws random decisions, whether it is
//! an unbiased estimator of Eq. 3 and which backends run it.
//!
//! Everything else is derived from here: the CLI's `--method` values and their help, which
//! options a method reads, the viewer's menus and sliders, the GPU kernel's method codes
//! (`METHOD_*` in `trace.wgsl`, checked by a test against [`MethodId::wgsl_constant`]), the
//! path tracer's choice of Gaussian estimator and the test lists that must cover every method.
//! A method's own math lives with its family ([`crate::trace`], [`crate::raster`],
//! [`crate::oracle`]); its identity lives here.

use crate::algorithm::Algorithm;
use crate::raster::{Blend, RasterSettings};
use crate::settings::RenderError;
use crate::trace::MAX_PRIMARY_SLOTS;

/// Particles per pass of the k-buffer (vk `PARTICLES_SPP`).
pub const DEFAULT_K: usize = 18;
/// Maximum passes of the k-buffer and stochastic pass (vk `maxPasses`).
pub const DEFAULT_MAX_PASSES: u32 = 200;
/// The k-buffer stops when transmittance drops to this (vk `minTransmittance`).
pub const DEFAULT_MIN_TRANSMITTANCE: f32 = 0.01;
/// Samples per traversal of `stochastic-n` (Sun et al. §3.5's n).
pub const DEFAULT_N: u32 = 16;
/// Traversals per frame of `stochastic-n` (§3.5's m).
pub const DEFAULT_M: u32 = 1;
/// Largest k of a k-buffer, and the most samples one traversal of the GPU kernel holds (fixed
/// arrays on the stack and in the GPU kernel's registers).
pub const MAX_HITS: usize = 64;
/// Largest n of `stochastic-n` (Sun et al. Table 5's 4 × 256): the CPU holds n slots in one
/// traversal; the GPU kernel, which holds [`MAX_HITS`], runs n > 64 as traversals of a divisor
/// of n (the same slots, so the same image; `splat_gpu::MethodParams`).
pub const MAX_SAMPLES_PER_TRAVERSAL: usize = 256;

/// Which renderer family runs a method.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Family {
    /// The brute-force oracle ([`crate::oracle`]).
    Oracle,
    /// Ray tracing through the BVH ([`crate::trace`]).
    Trace,
    /// Splatting ([`crate::raster`]).
    Raster,
}

/// A parameter that a method reads; its value lives in [`Parameters`].
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Param {
    /// Hits per pass, or accepted hits composited ([`Parameters::k`]).
    K,
    /// Pass limit ([`Parameters::max_passes`]).
    MaxPasses,
    /// Early-out transmittance of the k-buffer ([`Parameters::min_transmittance`]).
    MinTransmittance,
    /// Samples per traversal ([`Parameters::n`]).
    N,
    /// Traversals per frame ([`Parameters::m`]).
    M,
    /// Blend order of sorted splatting ([`Parameters::blend`]).
    Blend,
    /// The 3DGS rasterizer's early stop ([`RasterSettings::early_stop`]).
    EarlyStop,
    /// Laine–Karras's multiply–XOR scramble ([`Parameters::scramble`]).
    Scramble,
    /// Samples per pixel of splatting ([`RasterSettings::samples`]).
    RasterSamples,
    /// Where the samples lie ([`RasterSettings::sample_pattern`]).
    SamplePattern,
    /// Depth of a fragment ([`RasterSettings::fragment_depth`]).
    FragmentDepth,
    /// Footprint of a splat ([`RasterSettings::extent`]).
    Extent,
    /// How a fragment's alpha is evaluated ([`RasterSettings::response`]).
    Response,
}

/// The inclusive limits of a numeric parameter, and the top of its slider in an interactive
/// front end (a range a person explores, inside the limits).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Limits {
    /// Smallest value.
    pub min: f64,
    /// Largest value.
    pub max: f64,
    /// Largest value a slider offers.
    pub slider_max: f64,
}

/// How front ends name and bound a parameter.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ParamInfo {
    /// The CLI option that sets it, without the dashes.
    pub flag: &'static str,
    /// Its label in the viewer's panel (the sources' symbol where they have one).
    pub label: &'static str,
    /// Limits of a numeric parameter (`None` for a choice or a switch).
    pub limits: Option<Limits>,
}

impl Param {
    /// Every parameter.
    pub const ALL: [Param; 13] = [
        Param::K,
        Param::MaxPasses,
        Param::MinTransmittance,
        Param::N,
        Param::M,
        Param::Blend,
        Param::EarlyStop,
        Param::Scramble,
        Param::RasterSamples,
        Param::SamplePattern,
        Param::FragmentDepth,
        Param::Extent,
        Param::Response,
    ];

    /// Its names and limits.
    pub const fn info(self) -> ParamInfo {
        const fn count(max: f64, slider_max: f64) -> Option<Limits> {
            Some(Limits { min: 1.0, max, slider_max })
        }
        let (flag, label, limits) = match self {
            Param::K => ("k", "k (PARTICLES_SPP)", count(MAX_HITS as f64, MAX_HITS as f64)),
            Param::MaxPasses => ("max-passes", "max passes", count(MAX_PRIMARY_SLOTS as f64, 1000.0)),
            Param::MinTransmittance => {
                ("min-transmittance", "min transmittance", Some(Limits { min: 0.0, max: 1.0, slider_max: 0.2 }))
            }
            Param::N => (
                "samples-per-traversal",
                "n samples per traversal",
                count(MAX_SAMPLES_PER_TRAVERSAL as f64, MAX_SAMPLES_PER_TRAVERSAL as f64),
            ),
            Param::M => ("traversals", "m traversals", count(MAX_PRIMARY_SLOTS as f64, 16.0)),
            Param::Blend => ("blend", "blend", None),
            Param::EarlyStop => ("early-stop", "early stop", None),
            Param::Scramble => ("no-scramble", "scramble", None),
            Param::RasterSamples => ("raster-samples", "samples per pixel", None),
            Param::SamplePattern => ("sample-pattern", "sample pattern", None),
            Param::FragmentDepth => ("fragment-depth", "fragment depth", None),
            Param::Extent => ("extent", "extent", None),
            Param::Response => ("response", "response", None),
        };
        ParamInfo { flag, label, limits }
    }

    /// Check a numeric value against the limits.
    fn check(self, value: f64) -> Result<(), RenderError> {
        match self.info().limits {
            Some(Limits { min, max, .. }) if !(min..=max).contains(&value) => {
                Err(RenderError::Settings(format!("{} = {value} is outside {min}..={max}", self.info().label)))
            }
            _ => Ok(()),
        }
    }
}

/// One method of the catalogue.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Entry {
    /// Its key.
    pub id: MethodId,
    /// Its one name: `--method`, the viewer's menus, golden image files.
    pub name: &'static str,
    /// What it is, in a line (the CLI's help; the viewer's hover text).
    pub summary: &'static str,
    /// Which renderer runs it.
    pub family: Family,
    /// The parameters it reads.
    pub params: &'static [Param],
    /// Whether frames differ (it draws random decisions).
    pub stochastic: bool,
    /// Whether its expectation is Eq. 3 (for the raster family: sorted splatting), so the
    /// statistical tests must accept it; a biased method is a control they must reject, or a
    /// cost baseline.
    pub unbiased: bool,
    /// Whether the GPU backend has a kernel for it (support may still depend on the settings:
    /// `splat_gpu::supports`).
    pub gpu: bool,
}

/// Declares, from one row a method, its identity ([`MethodId`]), its [`Entry`] in
/// [`CATALOGUE`], the variant that carries its parameters ([`Method`] for ray tracing,
/// [`RasterMethod`] for splatting) and the two maps between them ([`MethodId::algorithm`],
/// [`Method::identity`], [`RasterMethod::id`]), so that a method cannot have one without the
/// others. A row is
///
/// ```text
/// /// doc of the variant
/// Id = code { name, (stochastic, unbiased, gpu), parameters read, summary } Variant { fields }
/// ```
///
/// where a ray-tracing variant is named as its identity and a field is named as the
/// [`Parameters`] field it takes its value from.
macro_rules! catalogue {
    (
        oracle {
            $oid:ident = $ocode:literal { $oname:literal, $oflags:tt, $oparams:expr, $osummary:literal $(,)? }
        }
        trace {$(
            $(#[doc = $tdoc:literal])*
            $tid:ident = $tcode:literal { $tname:literal, $tflags:tt, $tparams:expr, $tsummary:literal $(,)? }
            $({ $($(#[doc = $tfdoc:literal])* $tfield:ident: $tty:ty),* $(,)? })?
        ),* $(,)?}
        raster {$(
            $(#[doc = $rdoc:literal])*
            $rid:ident = $rcode:literal { $rname:literal, $rflags:tt, $rparams:expr, $rsummary:literal $(,)? }
            $rvariant:ident $({ $($(#[doc = $rfdoc:literal])* $rfield:ident: $rty:ty),* $(,)? })?
        ),* $(,)?}
    ) => {
        /// A rendering method without its parameters: what `--method` names and the viewer's
        /// menus list. The discriminant of a ray-tracing method is its code in the GPU kernel
        /// ([`MethodId::code`]). Each variant is a row of [`CATALOGUE`], which says what it is.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        #[repr(u32)]
        pub enum MethodId {
            #[doc = $osummary]
            $oid = $ocode,
            $(
                #[doc = $tsummary]
                $tid = $tcode,
            )*
            $(
                #[doc = $rsummary]
                $rid = $rcode,
            )*
        }

        /// Every method, in the order of [`MethodId`]'s discriminants (checked when the crate
        /// compiles, so that [`MethodId::entry`] is an index).
        pub const CATALOGUE: &[Entry] = &{
            let mut rows = [catalogue!(@entry $oid, $oname, Oracle, $oflags, $oparams, $osummary)
                $(, catalogue!(@entry $tid, $tname, Trace, $tflags, $tparams, $tsummary))*
                $(, catalogue!(@entry $rid, $rname, Raster, $rflags, $rparams, $rsummary))*];
            // Sort by discriminant (an insertion sort: const code has no `sort`).
            let mut i = 1;
            while i < rows.len() {
                let mut j = i;
                while j > 0 && (rows[j - 1].id as u32) > (rows[j].id as u32) {
                    let t = rows[j - 1];
                    rows[j - 1] = rows[j];
                    rows[j] = t;
                    j -= 1;
                }
                i += 1;
            }
            rows
        };

        /// A ray-tracing method with its parameters (its row in the [catalogue](crate::catalogue)
        /// says what it is; its function is in [`crate::trace`]).
        #[derive(Clone, Copy, Debug, PartialEq)]
        pub enum Method {
            $(
                $(#[doc = $tdoc])*
                $tid $({ $($(#[doc = $tfdoc])* $tfield: $tty),* })?,
            )*
        }

        /// A splatting method with its parameters (its row in the [catalogue](crate::catalogue)
        /// says what it is; its function is in [`crate::raster`]).
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        pub enum RasterMethod {
            $(
                $(#[doc = $rdoc])*
                $rvariant $({ $($(#[doc = $rfdoc])* $rfield: $rty),* })?,
            )*
        }

        impl MethodId {
            /// The method with `p`'s values for the parameters it reads (the others at their
            /// defaults: the early stop rides in [`RasterSettings`], which only sorted splatting
            /// reads).
            pub fn algorithm(self, p: &Parameters) -> Algorithm {
                let early_stop = self.reads(Param::EarlyStop) && p.raster.early_stop;
                let raster = |method| Algorithm::Raster(method, RasterSettings { early_stop, ..p.raster });
                match self {
                    MethodId::$oid => Algorithm::Oracle,
                    $(MethodId::$tid => Algorithm::Trace(Method::$tid { $($($tfield: p.$tfield),*)? }),)*
                    $(MethodId::$rid => raster(RasterMethod::$rvariant { $($($rfield: p.$rfield),*)? }),)*
                }
            }
        }

        impl Method {
            /// The method as the [catalogue](crate::catalogue) knows it: its entry, and its
            /// parameters (the others at their defaults); the inverse of [`MethodId::algorithm`].
            pub fn identity(&self) -> (MethodId, Parameters) {
                let defaults = Parameters::default();
                match *self {
                    $(Method::$tid { $($($tfield),*)? } => {
                        (MethodId::$tid, Parameters { $($($tfield,)*)? ..defaults })
                    })*
                }
            }
        }

        impl RasterMethod {
            /// The method's entry in the [catalogue](crate::catalogue).
            pub fn id(&self) -> MethodId {
                match self {
                    $(RasterMethod::$rvariant { .. } => MethodId::$rid,)*
                }
            }
        }
    };
    (@entry $id:ident, $name:literal, $family:ident, ($stochastic:literal, $unbiased:literal, $gpu:literal),
     $params:expr, $summary:literal) => {
        Entry {
            id: MethodId::$id,
            name: $name,
            summary: $summary,
            family: Family::$family,
            params: $params,
            stochastic: $stochastic,
            unbiased: $unbiased,
            gpu: $gpu,
        }
    };
}

/// The parameters of splatting every raster method reads.
const RASTER: [Param; 5] =
    [Param::RasterSamples, Param::SamplePattern, Param::FragmentDepth, Param::Extent, Param::Response];
/// The parameters of sorted splatting.
const SORTED: [Param; 7] = [
    Param::RasterSamples,
    Param::SamplePattern,
    Param::FragmentDepth,
    Param::Extent,
    Param::Response,
    Param::Blend,
    Param::EarlyStop,
];
/// The parameters of stratified transparency.
const STRATIFIED: [Param; 6] =
    [Param::RasterSamples, Param::SamplePattern, Param::FragmentDepth, Param::Extent, Param::Response, Param::Scramble];

// A row: the variant's doc, `Id = code { name, (stochastic, unbiased, GPU kernel), parameters,
// summary }`, then the variant with its fields (each named as the `Parameters` field it reads).
catalogue! {
    oracle {
        Oracle = 7 {
            "oracle", (false, true, false), &[],
            "The brute-force oracle: every particle tested for every pixel (no BVH), Eq. 3",
        }
    }
    trace {
        /// Every hit through the BVH, sorted, Eq. 3.
        Exact = 0 {
            "exact", (false, true, true), &[],
            "Every hit along each ray through the BVH, sorted, composited by Eq. 3",
        },
        /// 3DGRT / vk "all pass": k hits per pass kept sorted and integrated, the next pass
        /// restarting behind the last hit, until `max_passes` or transmittance ≤
        /// `min_transmittance`.
        KBuffer = 1 {
            "kbuffer", (false, true, true), &[Param::K, Param::MaxPasses, Param::MinTransmittance],
            "3DGRT / vk multi-pass k-buffer: k hits per pass, up to the pass limit",
        } {
            /// Hits per pass.
            k: usize,
            /// Pass limit.
            max_passes: u32,
            /// Early-out transmittance (0 disables it; above 0 the result is truncated, not
            /// exact).
            min_transmittance: f32,
        },
        /// Algorithm 1: one traversal, Russian roulette on alpha, closest accepted hit, t_max
        /// clipped on accept, one shading per ray.
        Stochastic = 2 {
            "stochastic", (true, true, true), &[],
            "Sun et al. Algorithm 1: one traversal, one accepted hit, one shading per ray",
        },
        /// §3.5: `m` traversals per frame, each carrying `n` independent instantiations.
        StochasticN = 3 {
            "stochastic-n", (true, true, true), &[Param::M, Param::N],
            "Sun et al. §3.5: m traversals of n samples each per frame",
        } {
            /// Traversals per frame.
            m: u32,
            /// Samples per traversal (≤ 64).
            n: u32,
        },
        /// vk stochastic pass: k sorted hits per pass, the pass accepted with probability
        /// 1 − T_pass and its radiance divided by it, else discarded.
        StochasticPass = 4 {
            "stochastic-pass", (true, true, true), &[Param::K, Param::MaxPasses],
            "vk stochastic pass: k sorted hits a pass, accepted with probability 1 − T_pass",
        } {
            /// Hits per pass.
            k: usize,
            /// Pass limit.
            max_passes: u32,
        },
        /// 3DGRT stochastic depth sampling: the first k accepted hits composited in order with
        /// their alphas. Biased (Sun et al. §5, Fig. 7): the control the tests must reject.
        DepthSampling = 5 {
            "depth-sampling-k", (true, false, true), &[Param::K],
            "3DGRT stochastic depth sampling of the first k accepted hits (biased; a control)",
        } {
            /// Accepted hits composited.
            k: usize,
        },
        /// Every particle as an opaque ellipsoid, its bounding ellipsoid in the BVH
        /// ([`bounding_radius`](crate::trace::bounding_radius): the cutoff, or nearer where a
        /// faint particle is culled sooner): the closest entry is shaded. Not an estimator of
        /// Eq. 3: the cost of a plain mesh-like ray through the same BVH, for benchmarks.
        Opaque = 6 {
            "opaque", (false, false, false), &[],
            "Every particle as an opaque ellipsoid (closest hit): a mesh-like cost baseline",
        },
    }
    raster {
        /// Global depth sort, then per-pixel blending: the raster oracle.
        RasterSorted = 8 {
            "raster-sorted", (false, true, true), &SORTED,
            "3DGS splatting: EWA projection, global depth sort, blended over or under per sample \
             (the raster oracle; under also gives iso depth and normals)",
        } Sorted {
            /// Over (back to front) or under (front to back).
            blend: Blend,
        },
        /// StochasticSplats / vk: no sort; a fragment is accepted when u < α (u hashed from
        /// pixel, frame, splat id and sample), written opaque under a depth test, else
        /// discarded.
        StochasticSplat = 9 {
            "stochastic-splat", (true, true, true), &RASTER,
            "StochasticSplats: no sort, depth-tested stochastic discard, S samples per pixel",
        } StochasticSplat,
        /// Enderton et al. 2010 as Laine & Karras compare against: depth test first, then
        /// R = ⌊α m + ξ⌋ of the m surviving covered samples, chosen at random, are written.
        Enderton = 10 {
            "enderton", (true, true, true), &RASTER,
            "Enderton et al. stochastic transparency: ⌊αS + ξ⌋ random samples of S per fragment",
        } Enderton,
        /// Laine & Karras 2011, Figure 7: per-sample opacity references from CalcAlphaRef,
        /// surface tracking by coverage bitmask, early depth test and sorting by stored depth.
        Stratified = 11 {
            "stratified", (true, true, true), &STRATIFIED,
            "Laine–Karras stratified stochastic transparency (CalcAlphaRef, surface tracking, sorting)",
        } Stratified {
            /// The multiply–XOR scramble of Figure 4 (`false`: the biased negative control).
            scramble: bool,
        },
    }
}

const _: () = {
    let mut i = 0;
    while i < CATALOGUE.len() {
        assert!(CATALOGUE[i].id as usize == i, "the catalogue is not in the order of MethodId");
        i += 1;
    }
};

impl MethodId {
    /// Every method, in catalogue order.
    pub const ALL: [MethodId; CATALOGUE.len()] = {
        let mut all = [MethodId::Exact; CATALOGUE.len()];
        let mut i = 0;
        while i < CATALOGUE.len() {
            all[i] = CATALOGUE[i].id;
            i += 1;
        }
        all
    };

    /// Its catalogue entry.
    pub const fn entry(self) -> &'static Entry {
        &CATALOGUE[self as usize]
    }

    /// Its one name.
    pub const fn name(self) -> &'static str {
        self.entry().name
    }

    /// The method of this name.
    pub fn from_name(name: &str) -> Option<MethodId> {
        CATALOGUE.iter().find(|e| e.name == name).map(|e| e.id)
    }

    /// Whether it reads `param`.
    pub fn reads(self, param: Param) -> bool {
        self.entry().params.contains(&param)
    }

    /// Its code in the GPU ray-tracing kernel (`params.method`, `METHOD_*`).
    pub const fn code(self) -> u32 {
        self as u32
    }

    /// The name of its constant in the GPU kernels: `METHOD_` and the name in capitals, dashes
    /// as underscores (`stochastic-n` is `METHOD_STOCHASTIC_N`).
    pub fn wgsl_constant(self) -> String {
        format!("METHOD_{}", self.name().to_uppercase().replace('-', "_"))
    }

    /// Every method of `family`, in catalogue order.
    pub fn of(family: Family) -> impl Iterator<Item = MethodId> {
        MethodId::ALL.into_iter().filter(move |m| m.entry().family == family)
    }
}

/// The value of every method parameter: what a front end holds while its user switches
/// methods. [`Default`] gives the sources' defaults (vk_gaussian_splatting's k = 18, 200
/// passes, 1 % transmittance; §3.5 with n = 16; sorted splatting front to back, which also
/// yields depth and normals; Laine–Karras with the scramble).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Parameters {
    /// Hits per pass (k-buffer, stochastic pass) or accepted hits composited (depth sampling).
    pub k: usize,
    /// Pass limit of the k-buffer and the stochastic pass.
    pub max_passes: u32,
    /// The k-buffer stops when transmittance falls to this (0: never).
    pub min_transmittance: f32,
    /// Samples per traversal of `stochastic-n`.
    pub n: u32,
    /// Traversals per frame of `stochastic-n`.
    pub m: u32,
    /// Blend order of sorted splatting.
    pub blend: Blend,
    /// The multiply–XOR scramble of stratified transparency (`false`: the biased control).
    pub scramble: bool,
    /// Samples, their pattern, fragment depth, footprint and early stop of splatting.
    pub raster: RasterSettings,
}

impl Default for Parameters {
    fn default() -> Self {
        Self {
            k: DEFAULT_K,
            max_passes: DEFAULT_MAX_PASSES,
            min_transmittance: DEFAULT_MIN_TRANSMITTANCE,
            n: DEFAULT_N,
            m: DEFAULT_M,
            blend: Blend::Under,
            scramble: true,
            raster: RasterSettings::default(),
        }
    }
}

impl Parameters {
    /// Check the numeric values against their [`Limits`].
    pub fn validate(&self) -> Result<(), RenderError> {
        Param::K.check(self.k as f64)?;
        Param::MaxPasses.check(f64::from(self.max_passes))?;
        Param::MinTransmittance.check(f64::from(self.min_transmittance))?;
        Param::N.check(f64::from(self.n))?;
        Param::M.check(f64::from(self.m))
    }

    /// Whether `self` and `other` differ in `param`.
    pub fn differs(&self, other: &Parameters, param: Param) -> bool {
        let (a, b) = (self, other);
        match param {
            Param::K => a.k != b.k,
            Param::MaxPasses => a.max_passes != b.max_passes,
            Param::MinTransmittance => a.min_transmittance != b.min_transmittance,
            Param::N => a.n != b.n,
            Param::M => a.m != b.m,
            Param::Blend => a.blend != b.blend,
            Param::EarlyStop => a.raster.early_stop != b.raster.early_stop,
            Param::Scramble => a.scramble != b.scramble,
            Param::RasterSamples => a.raster.samples != b.raster.samples,
            Param::SamplePattern => a.raster.sample_pattern != b.raster.sample_pattern,
            Param::FragmentDepth => a.raster.fragment_depth != b.raster.fragment_depth,
            Param::Extent => a.raster.extent != b.raster.extent,
            Param::Response => a.raster.response != b.raster.response,
        }
    }
}

impl Algorithm {
    /// The catalogue's methods it runs: one, or for the hybrid pipeline the splatting method
    /// and the ray-tracing method of its secondary rays.
    pub fn methods(&self) -> Vec<MethodId> {
        match self {
            Algorithm::Oracle => vec![MethodId::Oracle],
            Algorithm::Trace(m) => vec![m.id()],
            Algorithm::Raster(r, _) => vec![r.id()],
            Algorithm::Hybrid(r, _, m) => vec![r.id(), m.id()],
        }
    }

    /// Whether one of its methods reads `param`.
    pub fn reads(&self, param: Param) -> bool {
        self.methods().iter().any(|m| m.reads(param))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_method_has_one_name() {
        for entry in CATALOGUE {
            assert_eq!(MethodId::from_name(entry.name), Some(entry.id));
        }
        let names: std::collections::HashSet<_> = CATALOGUE.iter().map(|e| e.name).collect();
        assert_eq!(names.len(), CATALOGUE.len());
    }

    /// Each method built from the catalogue is that method again, in its family, with the
    /// catalogue's randomness, and reads exactly the parameters the catalogue lists: a
    /// parameter changed away from its default changes the method only when listed.
    #[test]
    fn every_entry_builds_its_own_method_and_reads_exactly_its_parameters() {
        let base = Parameters::default();
        base.validate().unwrap();
        let other = Parameters {
            k: 3,
            max_passes: 7,
            min_transmittance: 0.5,
            n: 5,
            m: 2,
            blend: Blend::Over,
            scramble: false,
            raster: RasterSettings {
                samples: 4,
                sample_pattern: crate::raster::SamplePattern::Standard,
                fragment_depth: crate::raster::FragmentDepth::MaxDensityPlane,
                extent: crate::raster::SplatExtent::Sqrt8,
                response: crate::raster::Response::AlongRay,
                early_stop: true,
                lk_variant: crate::raster::LkVariant::Paper,
            },
        };
        for id in MethodId::ALL {
            let algorithm = id.algorithm(&base);
            assert_eq!(algorithm.methods(), vec![id]);
            if let Algorithm::Trace(method) = algorithm {
                assert_eq!(method.identity(), (id, base), "{id:?}: identity is algorithm's inverse");
                let read = id.algorithm(&other);
                let Algorithm::Trace(read) = read else { unreachable!() };
                assert_eq!(read.identity().0, id);
                assert_eq!(id.algorithm(&read.identity().1), Algorithm::Trace(read), "{id:?}");
            }
            assert_eq!(algorithm.is_stochastic(), id.entry().stochastic, "{id:?}");
            let family = match algorithm {
                Algorithm::Oracle => Family::Oracle,
                Algorithm::Trace(_) => Family::Trace,
                Algorithm::Raster(..) | Algorithm::Hybrid(..) => Family::Raster,
            };
            assert_eq!(family, id.entry().family, "{id:?}");
            for param in Param::ALL {
                assert!(base.differs(&other, param), "{param:?}: the test's values must differ");
                let mut changed = base;
                for q in Param::ALL.into_iter().filter(|&q| q != param) {
                    // Copy every other parameter back to its default.
                    changed = with(&changed, &base, q);
                }
                let changed = with(&changed, &other, param);
                let moved = id.algorithm(&changed) != algorithm;
                assert_eq!(moved, id.reads(param), "{id:?} and {param:?}");
            }
        }
    }

    /// `into` with `from`'s value of `param`.
    fn with(into: &Parameters, from: &Parameters, param: Param) -> Parameters {
        let mut p = *into;
        match param {
            Param::K => p.k = from.k,
            Param::MaxPasses => p.max_passes = from.max_passes,
            Param::MinTransmittance => p.min_transmittance = from.min_transmittance,
            Param::N => p.n = from.n,
            Param::M => p.m = from.m,
            Param::Blend => p.blend = from.blend,
            Param::EarlyStop => p.raster.early_stop = from.raster.early_stop,
            Param::Scramble => p.scramble = from.scramble,
            Param::RasterSamples => p.raster.samples = from.raster.samples,
            Param::SamplePattern => p.raster.sample_pattern = from.raster.sample_pattern,
            Param::FragmentDepth => p.raster.fragment_depth = from.raster.fragment_depth,
            Param::Extent => p.raster.extent = from.raster.extent,
            Param::Response => p.raster.response = from.raster.response,
        }
        p
    }

    #[test]
    fn limits_refuse_what_the_methods_refuse() {
        for (p, bad) in [
            (Parameters { k: 0, ..Parameters::default() }, MethodId::KBuffer),
            (Parameters { k: MAX_HITS + 1, ..Parameters::default() }, MethodId::DepthSampling),
            (Parameters { n: MAX_SAMPLES_PER_TRAVERSAL as u32 + 1, ..Parameters::default() }, MethodId::StochasticN),
            (Parameters { m: 0, ..Parameters::default() }, MethodId::StochasticN),
            (Parameters { max_passes: MAX_PRIMARY_SLOTS + 1, ..Parameters::default() }, MethodId::StochasticPass),
        ] {
            assert!(p.validate().is_err(), "{p:?}");
            let Algorithm::Trace(method) = bad.algorithm(&p) else { unreachable!() };
            assert!(method.validate().is_err(), "{method:?}");
        }
    }
}
