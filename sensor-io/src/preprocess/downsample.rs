//! Median-filter downsampling and depth range clipping.

use crate::image::DepthImage;

/// Downsample by an integer `factor`, each output pixel being the median of the valid depths in
/// the `(factor+1)²` full-resolution neighbourhood of its sample (3×3 for QVGA from VGA, as the
/// honline capture code did; ANCHOR-FACTS §0). A pixel with fewer than half of its neighbourhood
/// valid stays empty, so silhouettes do not grow.
pub fn median_downsample(src: &DepthImage, factor: u32, out: &mut DepthImage) {
    let f = factor.max(1);
    out.width = src.width / f;
    out.height = src.height / f;
    out.data.resize(out.width as usize * out.height as usize, 0);
    let mut buf = [0u16; 25];
    let r = (f / 2 + (f % 2 == 0) as u32).min(2) as i64;
    for v in 0..out.height {
        for u in 0..out.width {
            let (cu, cv) = ((u * f) as i64, (v * f) as i64);
            let mut n = 0;
            let mut total = 0;
            for dv in -r + (f % 2 == 0) as i64..=r {
                for du in -r + (f % 2 == 0) as i64..=r {
                    let (x, y) = (cu + du, cv + dv);
                    if x < 0 || y < 0 || x >= src.width as i64 || y >= src.height as i64 {
                        continue;
                    }
                    total += 1;
                    let d = src.data[y as usize * src.width as usize + x as usize];
                    if d != 0 && n < buf.len() {
                        buf[n] = d;
                        n += 1;
                    }
                }
            }
            let value = if n * 2 >= total && n > 0 {
                let s = &mut buf[..n];
                s.sort_unstable();
                s[n / 2]
            } else {
                0
            };
            out.data[(v * out.width + u) as usize] = value;
        }
    }
}

/// Zero every depth outside `[near, far]` mm.
pub fn clip_range(depth: &mut DepthImage, near: u16, far: u16) {
    for d in &mut depth.data {
        if *d < near || *d > far {
            *d = 0;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_rejects_outliers_and_keeps_holes() {
        let mut src = DepthImage::zeros(8, 8);
        for d in &mut src.data {
            *d = 500;
        }
        src.data[2 * 8 + 2] = 9000; // a flying pixel
        for v in 4..8 {
            for u in 4..8 {
                src.data[v * 8 + u] = 0; // a hole
            }
        }
        let mut out = DepthImage::default();
        median_downsample(&src, 2, &mut out);
        assert_eq!((out.width, out.height), (4, 4));
        assert_eq!(out.get(1, 1), 500);
        assert_eq!(out.get(3, 3), 0);
        let mut c = out.clone();
        clip_range(&mut c, 600, 1000);
        assert_eq!(c.valid_count(), 0);
    }
}
