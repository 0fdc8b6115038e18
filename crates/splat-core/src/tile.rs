//! Screen tiles: the unit of parallel work of every CPU renderer. Tiles are processed in
//! parallel with the `rayon` feature; each tile's result depends only on the tile, so no image
//! depends on the thread count.

use crate::camera::Camera;

/// Side of the square pixel tiles.
pub const TILE: u32 = 16;

/// Number of [`TILE`] × [`TILE`] tiles covering a camera's image.
pub fn tile_count(camera: &Camera) -> u32 {
    camera.width.div_ceil(TILE) * camera.height.div_ceil(TILE)
}

/// Pixel range [x0, x1) × [y0, y1) of tile `tile` (row-major) of a camera's image.
pub fn tile_rect(camera: &Camera, tile: u32) -> (u32, u32, u32, u32) {
    let tiles_x = camera.width.div_ceil(TILE);
    let (x0, y0) = ((tile % tiles_x) * TILE, (tile / tiles_x) * TILE);
    (x0, y0, (x0 + TILE).min(camera.width), (y0 + TILE).min(camera.height))
}

/// The pixels (x, y) of tile `tile`, row by row.
pub fn tile_coords(camera: &Camera, tile: u32) -> impl Iterator<Item = (u32, u32)> {
    let (x0, y0, x1, y1) = tile_rect(camera, tile);
    (y0..y1).flat_map(move |y| (x0..x1).map(move |x| (x, y)))
}

/// `f` of every tile, in tile order; tiles run in parallel with the `rayon` feature. Each
/// tile's result depends only on the tile, so the output does not depend on the thread count.
pub fn map_tiles<T: Send>(camera: &Camera, f: impl Fn(u32) -> T + Sync + Send) -> Vec<T> {
    let tiles = 0..tile_count(camera);
    #[cfg(feature = "rayon")]
    {
        use rayon::prelude::*;
        tiles.into_par_iter().map(f).collect()
    }
    #[cfg(not(feature = "rayon"))]
    {
        tiles.map(f).collect()
    }
}
