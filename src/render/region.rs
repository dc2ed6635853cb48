//! A rectangle of the image: what `--region` renders and what a tile holds.
//!
//! A region's pixels are the same, bit for bit, as the full render's: every decision a pixel
//! depends on is made either from the whole frame's depth pass (which a region render
//! traces in full; it costs one ray per pixel) or inside the fixed bucket the pixel lies in
//! (see [`super::refine`]), and every sample is keyed by its pixel.

use std::fmt;
use std::str::FromStr;

use crate::error_kind::{ErrorKind, HasKind};

/// Columns `x0..x1` and rows `y0..y1` of an image (half-open: `x1` and `y1` are not in it).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct Region {
    /// First column (inclusive).
    pub x0: u32,
    /// First row (inclusive).
    pub y0: u32,
    /// End column (exclusive).
    pub x1: u32,
    /// End row (exclusive).
    pub y1: u32,
}

/// Why a region is not usable.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum RegionError {
    /// The text is not four comma-separated whole numbers `x0,y0,x1,y1`.
    #[error(
        "a region is x0,y0,x1,y1 in pixels (four whole numbers, x1 and y1 excluded), got {0:?}"
    )]
    Syntax(String),
    /// The region has no pixels (`x1 <= x0` or `y1 <= y0`).
    #[error("region {region} is empty: x1 must exceed x0 and y1 must exceed y0")]
    Empty {
        /// The region.
        region: Region,
    },
    /// The region reaches beyond the right or bottom edge of the image.
    #[error("region {region} reaches beyond the {width}x{height} image")]
    Outside {
        /// The region.
        region: Region,
        /// The image's width in pixels.
        width: u32,
        /// The image's height in pixels.
        height: u32,
    },
    /// The text is not a tile grid `COLUMNSxROWS` (or `N`) of 1 to 1024 each.
    #[error("a tile grid is COLUMNSxROWS (e.g. 4x4) of 1 to 1024 each, got {0:?}")]
    Grid(String),
    /// More columns than the image is wide or more rows than it is high (or none).
    #[error(
        "a {columns}x{rows} tile grid does not fit the {width}x{height} image: every tile needs at least one pixel"
    )]
    GridTooFine {
        /// Tile columns asked for.
        columns: u32,
        /// Tile rows asked for.
        rows: u32,
        /// The image's width in pixels.
        width: u32,
        /// The image's height in pixels.
        height: u32,
    },
}

impl Region {
    /// The whole `width` x `height` image.
    pub fn full(width: u32, height: u32) -> Self {
        Self {
            x0: 0,
            y0: 0,
            x1: width,
            y1: height,
        }
    }

    /// Width in pixels (`x1 - x0`).
    pub fn width(&self) -> u32 {
        self.x1 - self.x0
    }

    /// Height in pixels (`y1 - y0`).
    pub fn height(&self) -> u32 {
        self.y1 - self.y0
    }

    /// Whether pixel (`x`, `y`) lies in the region.
    pub fn contains(&self, x: u32, y: u32) -> bool {
        (self.x0..self.x1).contains(&x) && (self.y0..self.y1).contains(&y)
    }

    /// Whether the two share a pixel.
    pub fn overlaps(&self, other: &Region) -> bool {
        self.x0 < other.x1 && other.x0 < self.x1 && self.y0 < other.y1 && other.y0 < self.y1
    }

    /// Checks that the region is non-empty and inside a `width` x `height` image.
    pub fn check(&self, width: u32, height: u32) -> Result<(), RegionError> {
        if self.x1 <= self.x0 || self.y1 <= self.y0 {
            return Err(RegionError::Empty { region: *self });
        }
        if self.x1 > width || self.y1 > height {
            return Err(RegionError::Outside {
                region: *self,
                width,
                height,
            });
        }
        Ok(())
    }

    /// Copies the region's pixels out of a full-frame, row-major buffer of width `width`.
    pub fn crop<T: Copy>(&self, full: &[T], width: usize) -> Vec<T> {
        self.try_crop(full, width, "a region's pixels")
            .unwrap_or_else(|e| panic!("{e}"))
    }

    /// [`Region::crop`], or a [`MemoryError`](crate::limits::MemoryError) naming `what` when
    /// the copy cannot be allocated.
    pub fn try_crop<T: Copy>(
        &self,
        full: &[T],
        width: usize,
        what: &'static str,
    ) -> Result<Vec<T>, crate::limits::MemoryError> {
        let (w, h) = (self.width() as usize, self.height() as usize);
        let mut out = crate::limits::try_with_capacity(w * h, what)?;
        for y in self.y0 as usize..self.y1 as usize {
            let row = y * width;
            out.extend_from_slice(&full[row + self.x0 as usize..row + self.x1 as usize]);
        }
        Ok(out)
    }

    /// Copies a region-sized, row-major buffer (`per_pixel` elements to a pixel) into the
    /// region's place in a full-frame buffer of width `width`: the inverse of [`Region::crop`].
    /// False (nothing copied) when `src` is not the region's size.
    pub fn paste<T: Copy>(&self, src: &[T], dst: &mut [T], width: usize, per_pixel: usize) -> bool {
        let row = self.width() as usize * per_pixel;
        if src.len() != row * self.height() as usize {
            return false;
        }
        for (y, line) in src.chunks_exact(row).enumerate() {
            let at = ((self.y0 as usize + y) * width + self.x0 as usize) * per_pixel;
            dst[at..at + row].copy_from_slice(line);
        }
        true
    }

    /// Splits a `width` x `height` image into `columns` x `rows` tiles, row by row from the
    /// top left. Tile edges fall on multiples of 64 pixels where the tiles are large enough
    /// (the adaptive rule's buckets, which a tile edge would otherwise cut so both neighbours
    /// compute them), else on an even split.
    pub fn grid(
        width: u32,
        height: u32,
        columns: u32,
        rows: u32,
    ) -> Result<Vec<Region>, RegionError> {
        if columns == 0 || rows == 0 || columns > width || rows > height {
            return Err(RegionError::GridTooFine {
                columns,
                rows,
                width,
                height,
            });
        }
        let xs = cuts(width, columns);
        let ys = cuts(height, rows);
        Ok(ys
            .windows(2)
            .flat_map(|y| {
                xs.windows(2).map(move |x| Region {
                    x0: x[0],
                    y0: y[0],
                    x1: x[1],
                    y1: y[1],
                })
            })
            .collect())
    }
}

/// The edges of `n` parts of an axis of `len` pixels: on multiples of 64 when every part
/// stays non-empty that way, else an even split.
fn cuts(len: u32, n: u32) -> Vec<u32> {
    const ALIGN: u64 = 64;
    let even = |i: u32| (u64::from(len) * u64::from(i) / u64::from(n)) as u32;
    let aligned: Vec<u32> = (0..=n)
        .map(|i| match i {
            0 => 0,
            _ if i == n => len,
            _ => ((u64::from(even(i)) + ALIGN / 2) / ALIGN * ALIGN).min(u64::from(len)) as u32,
        })
        .collect();
    if aligned.windows(2).all(|w| w[1] > w[0]) {
        aligned
    } else {
        (0..=n).map(even).collect()
    }
}

impl fmt::Display for Region {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{},{},{},{}", self.x0, self.y0, self.x1, self.y1)
    }
}

impl FromStr for Region {
    type Err = RegionError;

    /// `x0,y0,x1,y1`, as [`Display`](fmt::Display) writes it.
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let v: Vec<u32> = s
            .split(',')
            .map(|p| p.trim().parse::<u32>())
            .collect::<Result<_, _>>()
            .map_err(|_| RegionError::Syntax(s.to_string()))?;
        let [x0, y0, x1, y1] = v[..] else {
            return Err(RegionError::Syntax(s.to_string()));
        };
        let region = Region { x0, y0, x1, y1 };
        if x1 <= x0 || y1 <= y0 {
            return Err(RegionError::Empty { region });
        }
        Ok(region)
    }
}

/// Parses a tile grid `COLUMNSxROWS` (e.g. `4x4`; a single number N means NxN).
pub fn parse_grid(s: &str) -> Result<(u32, u32), RegionError> {
    let bad = || RegionError::Grid(s.to_string());
    let n = |p: &str| {
        p.trim()
            .parse::<u32>()
            .ok()
            .filter(|v| (1..=1024).contains(v))
            .ok_or_else(bad)
    };
    match s.split_once(['x', 'X']) {
        Some((c, r)) => Ok((n(c)?, n(r)?)),
        None => n(s).map(|v| (v, v)),
    }
}

impl HasKind for RegionError {
    fn kind(&self) -> ErrorKind {
        ErrorKind::Usage
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn regions_parse_print_and_check() {
        let r: Region = "10, 20,110,220".parse().unwrap();
        assert_eq!(
            r,
            Region {
                x0: 10,
                y0: 20,
                x1: 110,
                y1: 220
            }
        );
        assert_eq!(r.to_string(), "10,20,110,220");
        assert_eq!((r.width(), r.height()), (100, 200));
        assert!(r.check(110, 220).is_ok());
        assert!(matches!(
            r.check(109, 220),
            Err(RegionError::Outside { .. })
        ));
        for bad in ["", "1,2,3", "1,2,3,4,5", "a,b,c,d", "-1,0,4,4"] {
            assert!(
                matches!(bad.parse::<Region>(), Err(RegionError::Syntax(_))),
                "{bad}"
            );
        }
        assert!(matches!(
            "5,0,5,4".parse::<Region>(),
            Err(RegionError::Empty { .. })
        ));
        let text = "1,2".parse::<Region>().unwrap_err().to_string();
        assert!(text.contains("x0,y0,x1,y1"), "{text}");
    }

    #[test]
    fn grids_cover_the_image_once_and_align_to_buckets_when_they_can() {
        for (w, h, c, r) in [
            (320, 240, 2, 2),
            (640, 480, 4, 3),
            (100, 7, 3, 7),
            (5, 5, 5, 1),
        ] {
            let tiles = Region::grid(w, h, c, r).unwrap();
            assert_eq!(tiles.len(), (c * r) as usize);
            let mut count = vec![0u8; (w * h) as usize];
            for t in &tiles {
                t.check(w, h).unwrap();
                for y in t.y0..t.y1 {
                    for x in t.x0..t.x1 {
                        count[(y * w + x) as usize] += 1;
                    }
                }
            }
            assert!(count.iter().all(|&n| n == 1), "{w}x{h} in {c}x{r}");
        }
        let tiles = Region::grid(640, 480, 4, 3).unwrap();
        assert!(
            tiles.iter().all(|t| t.x0 % 64 == 0 && t.y0 % 64 == 0),
            "{tiles:?}"
        );
        assert!(Region::grid(4, 4, 5, 1).is_err());
        assert_eq!(parse_grid("4x2"), Ok((4, 2)));
        assert_eq!(parse_grid("3"), Ok((3, 3)));
        for bad in ["0x2", "x", "4x", "2000x1", "ax1"] {
            assert!(parse_grid(bad).is_err(), "{bad}");
        }
    }
}
