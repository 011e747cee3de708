//! Nearest-neighbour resampling of row-major images (label maps, masks): a plain resize, and a resize
//! that also scales the content about a centre. Query masks come to the render resolution this way
//! ([`super::query`]), the segmenter-like degradation zooms its masks ([`super::oracle`]), and a
//! segmenter's measured zoom is undone (`eval-loc --prediction-zoom`).

/// Nearest-neighbour resize of a row-major `w` × `h` image to `tw` × `th`, sampling the source at the
/// target pixel centres.
pub fn resize_nearest<T: Copy + Default>(src: &[T], w: u32, h: u32, tw: u32, th: u32) -> Vec<T> {
    resize_scaled(src, [w, h], [tw, th], [0.0, 0.0], 1.0)
}

/// Nearest-neighbour resize of a row-major `[w, h]` image to `[tw, th]` whose content is also scaled
/// by `zoom` about `centre_px` (target pixels, pixel edges: the centre of pixel i is i + 0.5): target
/// pixel t shows the source at `(c + (t + 0.5 − c) / zoom) · n / tn`, so above 1 everything grows away
/// from the centre. A pixel whose source falls outside the image is `T::default()`.
pub fn resize_scaled<T: Copy + Default>(
    src: &[T],
    [w, h]: [u32; 2],
    [tw, th]: [u32; 2],
    centre_px: [f64; 2],
    zoom: f64,
) -> Vec<T> {
    debug_assert_eq!(src.len(), (w * h) as usize);
    let source = |t: u32, c: f64, n: u32, tn: u32| {
        let p = t as f64 + 0.5;
        // At zoom 1 the centre drops out exactly (c + (p − c) need not round back to p).
        let s = (if zoom == 1.0 { p } else { c + (p - c) / zoom }) * n as f64 / tn as f64;
        (s >= 0.0 && s < n as f64).then_some(s as usize)
    };
    let xs: Vec<Option<usize>> = (0..tw).map(|x| source(x, centre_px[0], w, tw)).collect();
    let mut out = vec![T::default(); (tw * th) as usize];
    for y in 0..th {
        let Some(sy) = source(y, centre_px[1], h, th) else { continue };
        let row = &src[sy * w as usize..(sy + 1) * w as usize];
        for (o, sx) in out[(y * tw) as usize..((y + 1) * tw) as usize].iter_mut().zip(&xs) {
            *o = sx.map_or_else(T::default, |sx| row[sx]);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn nearest_resize_samples_pixel_centres() {
        // 4×2 → 2×1: target pixel centres map to source x = 1, 3 (row 1).
        let ids = [1u32, 2, 3, 4, 5, 6, 7, 8];
        assert_eq!(resize_nearest(&ids, 4, 2, 2, 1), vec![6, 8]);
        assert_eq!(resize_nearest(&ids, 4, 2, 4, 2), ids.to_vec());
        // Upsampling repeats pixels.
        assert_eq!(resize_nearest(&[1u8, 2], 2, 1, 4, 1), vec![1, 1, 2, 2]);
    }
}
