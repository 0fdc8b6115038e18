//! Sub-pixel sample sets of the MSAA-like raster methods.

use glam::Vec2;

/// Largest number of samples per pixel (one bit each in a `u64` coverage mask).
pub const MAX_SAMPLES: u32 = 64;

/// The sample counts the raster methods accept.
pub const SAMPLE_COUNTS: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];

/// The sample counts that have a standard pattern ([`SamplePattern::Standard`]).
pub const STANDARD_COUNTS: [u32; 5] = [1, 2, 4, 8, 16];

/// Where the S samples of a pixel lie.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum SamplePattern {
    /// The Hammersley set, a Latin square for every power of two (S up to 64).
    #[default]
    Hammersley,
    /// The standard multisample positions of Vulkan (`standardSampleLocations`) and Direct3D
    /// (`D3D11_STANDARD_MULTISAMPLE_PATTERN`), which Metal uses too: where MSAA hardware puts
    /// its samples, so that the CPU reference and a GPU frame decide sample for sample
    /// (S = 1, 2, 4, 8, 16).
    Standard,
}

/// The standard positions in 1/16 pixel from the pixel's top-left corner, sample i at index i
/// (the Vulkan specification's "Standard sample locations" table; Direct3D's offsets from the
/// centre plus 8).
const STANDARD_2: [[u8; 2]; 2] = [[12, 12], [4, 4]];
const STANDARD_4: [[u8; 2]; 4] = [[6, 2], [14, 6], [2, 10], [10, 14]];
const STANDARD_8: [[u8; 2]; 8] = [[9, 5], [7, 11], [13, 9], [5, 3], [3, 13], [1, 7], [11, 15], [15, 1]];
const STANDARD_16: [[u8; 2]; 16] = [
    [9, 9],
    [7, 5],
    [5, 10],
    [12, 7],
    [3, 6],
    [10, 13],
    [13, 11],
    [11, 3],
    [6, 14],
    [8, 1],
    [4, 2],
    [2, 12],
    [0, 8],
    [15, 4],
    [14, 15],
    [1, 0],
];

impl SamplePattern {
    /// Whether the pattern has `count` samples.
    pub fn has(self, count: u32) -> bool {
        match self {
            SamplePattern::Hammersley => SAMPLE_COUNTS.contains(&count),
            SamplePattern::Standard => STANDARD_COUNTS.contains(&count),
        }
    }

    /// The pattern's name in the CLI.
    pub fn name(self) -> &'static str {
        match self {
            SamplePattern::Hammersley => "hammersley",
            SamplePattern::Standard => "standard",
        }
    }
}

/// Sub-pixel positions in [0, 1)² of the `count` samples of a pixel in `pattern`, sample i at
/// index i; S = 1 is the centre in both. Empty when the pattern has no `count`
/// ([`SamplePattern::has`]).
pub fn sample_positions(count: u32, pattern: SamplePattern) -> Vec<Vec2> {
    match pattern {
        SamplePattern::Hammersley if pattern.has(count) => hammersley(count),
        SamplePattern::Standard => {
            let sixteenths: &[[u8; 2]] = match count {
                1 => &[[8, 8]],
                2 => &STANDARD_2,
                4 => &STANDARD_4,
                8 => &STANDARD_8,
                16 => &STANDARD_16,
                _ => &[],
            };
            sixteenths.iter().map(|&[x, y]| Vec2::new(f32::from(x), f32::from(y)) / 16.0).collect()
        }
        SamplePattern::Hammersley => Vec::new(),
    }
}

/// The Hammersley set ((i + ½)/S, (ρ(i) + ½)/S) with ρ the base-2 radical inverse. For a power
/// of two S every row and every column of the S × S grid holds exactly one sample.
fn hammersley(count: u32) -> Vec<Vec2> {
    let s = count as f32;
    (0..count)
        .map(|i| {
            let radical = if count == 1 { 0.0 } else { (i.reverse_bits() >> (32 - count.trailing_zeros())) as f32 };
            Vec2::new((i as f32 + 0.5) / s, (radical + 0.5) / s)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn hammersley_samples_are_a_latin_square() {
        assert_eq!(sample_positions(1, SamplePattern::Hammersley), vec![Vec2::splat(0.5)]);
        for s in SAMPLE_COUNTS {
            let p = sample_positions(s, SamplePattern::Hammersley);
            assert_eq!(p.len(), s as usize);
            let mut rows = vec![false; s as usize];
            let mut cols = vec![false; s as usize];
            for q in &p {
                assert!(q.x > 0.0 && q.x < 1.0 && q.y > 0.0 && q.y < 1.0);
                let (c, r) = ((q.x * s as f32) as usize, (q.y * s as f32) as usize);
                assert!(!rows[r] && !cols[c], "S = {s}: row {r} or column {c} twice");
                rows[r] = true;
                cols[c] = true;
            }
        }
    }

    /// The standard patterns: S distinct positions in [0, 1)², centred on the pixel centre
    /// (their mean is (½, ½)), each a Latin square of the S × S grid for S ≤ 8 (Direct3D's
    /// design); 32 and 64 have none.
    #[test]
    fn standard_patterns_are_centred_and_distinct() {
        assert_eq!(sample_positions(1, SamplePattern::Standard), vec![Vec2::splat(0.5)]);
        for s in STANDARD_COUNTS {
            let p = sample_positions(s, SamplePattern::Standard);
            assert_eq!(p.len(), s as usize);
            let mean = p.iter().sum::<Vec2>() / s as f32;
            assert!((mean - Vec2::splat(0.5)).length() < 1.0 / 16.0, "S = {s}: mean {mean}");
            for (i, a) in p.iter().enumerate() {
                assert!(a.min_element() >= 0.0 && a.max_element() < 1.0);
                assert!(p[..i].iter().all(|b| a != b), "S = {s}: sample {i} repeated");
            }
            if s <= 8 {
                let cell = |v: f32| (v * s as f32) as usize;
                for (i, a) in p.iter().enumerate() {
                    let clash = p[..i].iter().any(|b| cell(a.x) == cell(b.x) || cell(a.y) == cell(b.y));
                    assert!(!clash, "S = {s}: sample {i} shares a row or column");
                }
            }
        }
        for s in [32, 64, 3] {
            assert!(!SamplePattern::Standard.has(s) && sample_positions(s, SamplePattern::Standard).is_empty());
        }
    }
}
