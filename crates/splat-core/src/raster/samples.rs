//! Sub-pixel sample sets of the MSAA-like raster methods.

use glam::Vec2;

/// Largest number of samples per pixel (one bit each in a `u64` coverage mask).
pub const MAX_SAMPLES: u32 = 64;

/// The sample counts the raster methods accept.
pub const SAMPLE_COUNTS: [u32; 7] = [1, 2, 4, 8, 16, 32, 64];

/// Sub-pixel positions in [0, 1)² of the `count` samples of a pixel: the Hammersley set
/// ((i + ½)/S, (ρ(i) + ½/S)) with ρ the base-2 radical inverse. For a power of two S every
/// row and every column of the S × S grid holds exactly one sample; S = 1 is the centre.
pub fn sample_positions(count: u32) -> Vec<Vec2> {
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
    fn samples_are_a_latin_square() {
        assert_eq!(sample_positions(1), vec![Vec2::splat(0.5)]);
        for s in SAMPLE_COUNTS {
            let p = sample_positions(s);
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
}
