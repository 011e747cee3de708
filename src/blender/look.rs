//! Per-frame look variety: sun from a date and time at the area's latitude, sky (clear, hazy, overcast),
//! distance haze, exposure and white balance, and camera effects (vignetting, blur, sensor noise,
//! optional JPEG re-encoding).
//!
//! [`FrameLook::draw`] draws one frame's values from the look seed and the frame *name* only, so a frame
//! looks the same whether it is rendered alone, in a batch or in a shard. The values are written into the
//! Blender job (sun, sky, haze, exposure: applied per frame by `render_rgb.py`) and into the frame's
//! `rgb/<frame>.render.json` and COCO image record, so users can filter and ablate. White balance and the
//! camera effects are applied by insgen to the 8-bit PNG Blender wrote ([`apply_camera_effects`]); the
//! optional EXR stays the linear scene render without them.
//!
//! [`LookStyle::Plain`] keeps the fixed look of earlier versions (one sun per area and seed, clear sky,
//! no haze, no effects).

use rand::{Rng, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::util::fnv1a_seeded;

pub use super::error::{EffectsError, LookError};

/// Whether frames vary.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum LookStyle {
    /// Sun, sky, haze, exposure, white balance and camera effects drawn per frame.
    #[default]
    Varied,
    /// One sun per area and seed, a clear sky, no haze and no camera effects (the earlier look).
    Plain,
}

impl LookStyle {
    /// The style's name in files and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LookStyle::Varied => "varied",
            LookStyle::Plain => "plain",
        }
    }
}

/// The weather of a frame.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Sky {
    /// Blue sky, hard sun shadows, distant haze only.
    Clear,
    /// Pale sky, weaker sun, visibility of a few kilometres.
    Hazy,
    /// Grey sky, the sun behind clouds (soft, weak shadows), bright diffuse light.
    Overcast,
}

/// Where the sun of a varied frame comes from.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case")]
pub enum SunRange {
    /// A day of the year and a local solar time drawn uniformly, the sun's position computed at the
    /// area's latitude; draws with the sun below `min_elevation_deg` are redrawn.
    Dates {
        /// Latitude the sun is computed at, degrees.
        latitude_deg: f64,
        /// First and last day of the year (1..=366).
        days: [u32; 2],
        /// First and last local solar time, hours.
        solar_hours: [f64; 2],
        /// Lowest accepted sun elevation, degrees.
        min_elevation_deg: f64,
    },
    /// Azimuth (clockwise from north) and elevation drawn uniformly in the ranges, degrees.
    Angles {
        /// Azimuth range, degrees clockwise from north.
        azimuth_deg: [f64; 2],
        /// Elevation range, degrees above the horizon.
        elevation_deg: [f64; 2],
    },
}

/// Ranges the varied look draws from (the `render-rgb` flags).
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LookRanges {
    /// Varied or plain.
    pub style: LookStyle,
    /// Where the sun comes from.
    pub sun: SunRange,
    /// Relative weights of clear, hazy and overcast skies.
    pub sky_weights: [f64; 3],
    /// Exposure jitter, stops (± this).
    pub exposure_jitter_ev: f64,
    /// White balance: the colour temperature the camera assumed, kelvin (6500 = neutral).
    pub white_balance_k: [f64; 2],
    /// Camera effects on or off (vignetting, blur, sensor noise).
    pub camera_effects: bool,
    /// JPEG re-encoding quality range (the PNG then holds the decoded JPEG); `None` = off.
    pub jpeg_quality: Option<[u8; 2]>,
}

impl LookRanges {
    /// The defaults at a latitude: any day, 07–18 h solar time with the sun ≥ 15° up; clear 50 %,
    /// hazy 30 %, overcast 20 %; ±0.3 EV; 5000–7500 K; camera effects on; no JPEG.
    pub fn defaults(latitude_deg: f64) -> Self {
        LookRanges {
            style: LookStyle::Varied,
            sun: SunRange::Dates {
                latitude_deg,
                days: [1, 365],
                solar_hours: [7.0, 18.0],
                min_elevation_deg: 15.0,
            },
            sky_weights: [0.5, 0.3, 0.2],
            exposure_jitter_ev: 0.3,
            white_balance_k: [5000.0, 7500.0],
            camera_effects: true,
            jpeg_quality: None,
        }
    }

    /// The plain look (the ranges other than the style are kept but unused).
    pub fn plain(latitude_deg: f64) -> Self {
        LookRanges { style: LookStyle::Plain, ..Self::defaults(latitude_deg) }
    }

    /// Checks the ranges.
    ///
    /// # Errors
    /// The first range that is out of bounds or not increasing, with its values.
    pub fn check(&self) -> Result<(), LookError> {
        let ordered = |name: &'static str, range: [f64; 2]| {
            let [a, b] = range;
            if a.is_finite() && b.is_finite() && a <= b {
                Ok(())
            } else {
                Err(LookError::NotIncreasing { name, range })
            }
        };
        match self.sun {
            SunRange::Dates { latitude_deg, days, solar_hours, min_elevation_deg } => {
                if !(-90.0..=90.0).contains(&latitude_deg) {
                    return Err(LookError::Latitude { latitude_deg });
                }
                if days[0] < 1 || days[1] > 366 || days[0] > days[1] {
                    return Err(LookError::SunDays { days });
                }
                ordered("sun hours", solar_hours)?;
                if solar_hours[0] < 0.0 || solar_hours[1] > 24.0 {
                    return Err(LookError::SunHours { solar_hours });
                }
                if !(-90.0..90.0).contains(&min_elevation_deg) {
                    return Err(LookError::MinElevation { min_elevation_deg });
                }
            }
            SunRange::Angles { azimuth_deg, elevation_deg } => {
                ordered("sun azimuth", azimuth_deg)?;
                ordered("sun elevation", elevation_deg)?;
                if elevation_deg[0] < 0.0 || elevation_deg[1] > 90.0 {
                    return Err(LookError::SunElevation { elevation_deg });
                }
            }
        }
        if self.sky_weights.iter().any(|w| !(w.is_finite() && *w >= 0.0))
            || self.sky_weights.iter().sum::<f64>() <= 0.0
        {
            return Err(LookError::SkyWeights { weights: self.sky_weights });
        }
        if !(self.exposure_jitter_ev.is_finite() && self.exposure_jitter_ev >= 0.0) {
            return Err(LookError::ExposureJitter { jitter_ev: self.exposure_jitter_ev });
        }
        ordered("white balance", self.white_balance_k)?;
        if self.white_balance_k[0] < 1000.0 || self.white_balance_k[1] > 40000.0 {
            return Err(LookError::WhiteBalance { kelvin: self.white_balance_k });
        }
        if let Some(quality) = self.jpeg_quality {
            let [a, b] = quality;
            if a == 0 || b > 100 || a > b {
                return Err(LookError::JpegQuality { quality });
            }
        }
        Ok(())
    }
}

/// Camera effects of one frame, applied by insgen to the 8-bit frame.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CameraEffects {
    /// Colour temperature the camera assumed, kelvin: below 6500 the frame turns bluer, above warmer.
    pub white_balance_k: f64,
    /// Darkening at the image corners (0 = none; the factor is 1 − v·r², r = 1 at a corner).
    pub vignetting: f64,
    /// Gaussian blur, standard deviation in pixels (0 = none).
    pub blur_sigma_px: f64,
    /// Sensor noise, standard deviation in 8-bit levels (0 = none).
    pub noise_sigma: f64,
    /// JPEG quality the frame was re-encoded with, when it was.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub jpeg_quality: Option<u8>,
}

impl CameraEffects {
    /// No effect at all.
    pub const NONE: CameraEffects = CameraEffects {
        white_balance_k: 6500.0,
        vignetting: 0.0,
        blur_sigma_px: 0.0,
        noise_sigma: 0.0,
        jpeg_quality: None,
    };

    /// Whether no effect is applied at all.
    pub fn is_none(&self) -> bool {
        *self == Self::NONE
    }
}

/// Contrast classes of the LoD buildings ([`crate::scene::adjacency`]): the procedural look picks each
/// building's facade and roof colours from the band of its palette (sorted by lightness) that its class
/// names, so buildings that touch in plan differ in lightness and their shared edge shows in the photo.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct BuildingContrast {
    /// Number of classes (bands of each palette).
    pub classes: u8,
    /// `[building ID, class]`, sorted by ID.
    pub building_classes: Vec<[u32; 2]>,
}

impl BuildingContrast {
    /// Classes of touching buildings (cells of [`CONTRAST_CELL_M`], reach [`CONTRAST_REACH_M`]) and the
    /// number of touching pairs whose classes still clash, of all touching pairs.
    pub fn of_mesh(mesh: &crate::scene::SceneMesh) -> (BuildingContrast, (usize, usize)) {
        use crate::scene::adjacency::{clashes, contrast_classes, plan_neighbours};
        let neighbours = plan_neighbours(mesh, CONTRAST_CELL_M, CONTRAST_REACH_M);
        let classes = contrast_classes(&neighbours, CONTRAST_CLASSES);
        let clash = clashes(&neighbours, &classes);
        let building_classes = classes.into_iter().map(|(id, c)| [id, u32::from(c)]).collect();
        (BuildingContrast { classes: CONTRAST_CLASSES, building_classes }, clash)
    }
}

/// Contrast classes of the procedural look: four bands per palette (plan graphs of cities are near planar).
pub const CONTRAST_CLASSES: u8 = 4;
/// Plan cell of the neighbour search, metres.
pub const CONTRAST_CELL_M: f64 = 0.5;
/// Buildings closer than this in plan count as touching, metres (about a pixel of a UAV view).
pub const CONTRAST_REACH_M: f64 = 1.0;

/// One frame's drawn look: what Blender sets before rendering it and what insgen applies after.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct FrameLook {
    /// Varied or plain.
    pub style: LookStyle,
    /// Sun azimuth clockwise from north and elevation above the horizon, degrees.
    pub sun_azimuth_deg: f64,
    /// Sun elevation above the horizon, degrees.
    pub sun_elevation_deg: f64,
    /// The day of the year and local solar time (hours) the sun was computed for, when drawn by date.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub day_of_year: Option<u32>,
    /// Local solar time, hours (drawn by date only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub solar_time_h: Option<f64>,
    /// The weather.
    pub sky: Sky,
    /// Sun lamp irradiance (Blender's sun strength) and sky strength.
    pub sun_strength: f64,
    /// Sky strength (Blender's world background strength).
    pub sky_strength: f64,
    /// Meteorological visibility, metres (haze reaches 95 % at this distance); `None` = no haze.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub visibility_m: Option<f64>,
    /// Linear RGB radiance of the haze (per unit of sky strength).
    pub haze_rgb: [f64; 3],
    /// Exposure, stops.
    pub exposure_ev: f64,
    /// Camera effects insgen applies to the 8-bit frame.
    pub camera: CameraEffects,
}

/// The plain look's sun for a seed: azimuth uniform in [0°, 360°), elevation uniform in [30°, 65°].
pub fn sun_from_seed(seed: u64) -> (f64, f64) {
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed ^ 0x5u64.rotate_left(60));
    (rng.gen_range(0.0..360.0), rng.gen_range(30.0..65.0))
}

/// Sun lamp irradiance and sky strength of the plain look.
pub const PLAIN_SUN_STRENGTH: f64 = 4.0;
/// Sky strength of the plain look.
pub const PLAIN_SKY_STRENGTH: f64 = 0.18;

/// Solar position (azimuth clockwise from north, elevation), degrees, for a latitude, a day of the year
/// and a local solar time in hours (12 = solar noon). Cooper's declination and the hour angle: within
/// about half a degree of an ephemeris, which is plenty for lighting.
pub fn solar_position_deg(latitude_deg: f64, day_of_year: u32, solar_time_h: f64) -> (f64, f64) {
    let decl =
        (23.44f64).to_radians() * (2.0 * std::f64::consts::PI * (284.0 + day_of_year as f64) / 365.0).sin();
    let phi = latitude_deg.to_radians();
    let h = (15.0 * (solar_time_h - 12.0)).to_radians();
    let sin_el = phi.sin() * decl.sin() + phi.cos() * decl.cos() * h.cos();
    let el = sin_el.clamp(-1.0, 1.0).asin();
    let az = (-h.sin() * decl.cos()).atan2(decl.sin() * phi.cos() - decl.cos() * phi.sin() * h.cos());
    (az.to_degrees().rem_euclid(360.0), el.to_degrees())
}

impl FrameLook {
    /// Seed of the sensor noise of frame `name` (independent of the draws of [`FrameLook::draw`]).
    pub fn noise_seed(look_seed: u64, name: &str) -> u64 {
        look_seed.rotate_left(29) ^ fnv1a_seeded(0, name) ^ 0x006e_6f69_7365_u64
    }

    /// The look of frame `name` under `ranges` and `look_seed` (the plan's seed of the sun and materials).
    ///
    /// # Errors
    /// [`LookError::SunNeverUp`]: the sun never rises above the minimum elevation in the given days and
    /// hours at that latitude.
    pub fn draw(ranges: &LookRanges, look_seed: u64, name: &str) -> Result<FrameLook, LookError> {
        if ranges.style == LookStyle::Plain {
            return Ok(FrameLook::plain(look_seed));
        }
        let mut rng =
            rand_chacha::ChaCha8Rng::seed_from_u64(look_seed ^ fnv1a_seeded(0, name).rotate_left(17));
        let sun = draw_sun(&ranges.sun, &mut rng)?;
        let sky = draw_sky(&ranges.sky_weights, &mut rng);
        // Sun weaker through a longer air path at low elevation, and through haze and cloud.
        let air = (sun.elevation_deg.to_radians().sin()).max(0.05).powf(0.25);
        let (sun_k, sky_k, vis_km, haze) = match sky {
            Sky::Clear => (
                rng.gen_range(0.95..1.1),
                rng.gen_range(0.85..1.15),
                rng.gen_range(25.0..60.0),
                [0.55, 0.65, 0.80],
            ),
            Sky::Hazy => (
                rng.gen_range(0.6..0.8),
                rng.gen_range(1.2..1.5),
                rng.gen_range(3.0..10.0),
                [0.72, 0.74, 0.76],
            ),
            Sky::Overcast => (
                rng.gen_range(0.08..0.2),
                rng.gen_range(2.6..3.4),
                rng.gen_range(6.0..15.0),
                [0.62, 0.63, 0.65],
            ),
        };
        let exposure_ev = if ranges.exposure_jitter_ev > 0.0 {
            rng.gen_range(-ranges.exposure_jitter_ev..ranges.exposure_jitter_ev)
        } else {
            0.0
        };
        let camera = draw_camera_effects(ranges, &mut rng);
        Ok(FrameLook {
            style: LookStyle::Varied,
            sun_azimuth_deg: round_to(sun.azimuth_deg, 3),
            sun_elevation_deg: round_to(sun.elevation_deg, 3),
            day_of_year: sun.day_of_year,
            solar_time_h: sun.solar_time_h,
            sky,
            sun_strength: round_to(PLAIN_SUN_STRENGTH * sun_k * air, 4),
            sky_strength: round_to(PLAIN_SKY_STRENGTH * sky_k, 4),
            visibility_m: Some(round_to(vis_km * 1000.0, 0)),
            haze_rgb: haze,
            exposure_ev: round_to(exposure_ev, 3),
            camera,
        })
    }

    /// The plain look: the seed's sun, a clear sky, no haze, no effects.
    fn plain(look_seed: u64) -> FrameLook {
        let (az, el) = sun_from_seed(look_seed);
        FrameLook {
            style: LookStyle::Plain,
            sun_azimuth_deg: az,
            sun_elevation_deg: el,
            day_of_year: None,
            solar_time_h: None,
            sky: Sky::Clear,
            sun_strength: PLAIN_SUN_STRENGTH,
            sky_strength: PLAIN_SKY_STRENGTH,
            visibility_m: None,
            haze_rgb: [0.0; 3],
            exposure_ev: 0.0,
            camera: CameraEffects::NONE,
        }
    }
}

/// `v` rounded to `digits` decimals (what the frame records).
fn round_to(v: f64, digits: i32) -> f64 {
    let s = 10f64.powi(digits);
    (v * s).round() / s
}

/// A drawn sun: its position, and the date and time it was computed for when drawn by date.
struct DrawnSun {
    azimuth_deg: f64,
    elevation_deg: f64,
    day_of_year: Option<u32>,
    solar_time_h: Option<f64>,
}

/// Draws the sun: by date and solar time (redrawn up to 1000 times while below the minimum elevation),
/// or by angles.
fn draw_sun(sun: &SunRange, rng: &mut rand_chacha::ChaCha8Rng) -> Result<DrawnSun, LookError> {
    match *sun {
        SunRange::Dates { latitude_deg, days, solar_hours, min_elevation_deg } => {
            for _ in 0..1000 {
                let day = rng.gen_range(days[0]..=days[1]);
                let hour = if solar_hours[0] < solar_hours[1] {
                    rng.gen_range(solar_hours[0]..solar_hours[1])
                } else {
                    solar_hours[0]
                };
                // Recorded to the millisecond-hour: the position is that of the recorded time.
                let hour = (hour * 1000.0).round() / 1000.0;
                let (az, el) = solar_position_deg(latitude_deg, day, hour);
                if el >= min_elevation_deg {
                    return Ok(DrawnSun {
                        azimuth_deg: az,
                        elevation_deg: el,
                        day_of_year: Some(day),
                        solar_time_h: Some(hour),
                    });
                }
            }
            Err(LookError::SunNeverUp { latitude_deg, days, solar_hours, min_elevation_deg })
        }
        SunRange::Angles { azimuth_deg, elevation_deg } => {
            let draw = |rng: &mut rand_chacha::ChaCha8Rng, [a, b]: [f64; 2]| {
                if a < b {
                    rng.gen_range(a..b)
                } else {
                    a
                }
            };
            let az = draw(rng, azimuth_deg).rem_euclid(360.0);
            Ok(DrawnSun {
                azimuth_deg: az,
                elevation_deg: draw(rng, elevation_deg),
                day_of_year: None,
                solar_time_h: None,
            })
        }
    }
}

/// Draws the sky by the relative weights of clear, hazy and overcast.
fn draw_sky(weights: &[f64; 3], rng: &mut rand_chacha::ChaCha8Rng) -> Sky {
    let total: f64 = weights.iter().sum();
    let pick = rng.gen_range(0.0..total);
    if pick < weights[0] {
        Sky::Clear
    } else if pick < weights[0] + weights[1] {
        Sky::Hazy
    } else {
        Sky::Overcast
    }
}

/// Draws white balance, vignetting, blur, noise and JPEG quality (in that order).
fn draw_camera_effects(ranges: &LookRanges, rng: &mut rand_chacha::ChaCha8Rng) -> CameraEffects {
    let [k0, k1] = ranges.white_balance_k;
    let white_balance_k = if k0 < k1 { rng.gen_range(k0..k1) } else { k0 };
    let (vignetting, blur_sigma_px, noise_sigma) = if ranges.camera_effects {
        (rng.gen_range(0.0..0.3), rng.gen_range(0.0..0.7), rng.gen_range(0.5..3.0))
    } else {
        (0.0, 0.0, 0.0)
    };
    let jpeg_quality = ranges.jpeg_quality.map(|[a, b]| rng.gen_range(a..=b));
    CameraEffects {
        white_balance_k: round_to(white_balance_k, 0),
        vignetting: round_to(vignetting, 3),
        blur_sigma_px: round_to(blur_sigma_px, 3),
        noise_sigma: round_to(noise_sigma, 3),
        jpeg_quality,
    }
}

/// Linear RGB of a black body at `kelvin`, normalised to green = 1 (Planck's law integrated against
/// narrow bands at the sRGB primaries' dominant wavelengths; good enough for a white-balance gain).
fn blackbody_rgb(kelvin: f64) -> [f64; 3] {
    let planck = |nm: f64| {
        let l = nm * 1e-9;
        1.0 / (l.powi(5) * ((1.4388e-2 / (l * kelvin)).exp() - 1.0))
    };
    let [r, g, b] = [planck(610.0), planck(550.0), planck(465.0)];
    [r / g, 1.0, b / g]
}

/// Per-channel gains of a camera that assumed `kelvin` for a scene lit at 6500 K (green = 1).
pub fn white_balance_gains(kelvin: f64) -> [f64; 3] {
    let scene = blackbody_rgb(6500.0);
    let assumed = blackbody_rgb(kelvin);
    [scene[0] / assumed[0], 1.0, scene[2] / assumed[2]]
}

fn srgb_to_linear(v: f64) -> f64 {
    if v <= 0.04045 {
        v / 12.92
    } else {
        ((v + 0.055) / 1.055).powf(2.4)
    }
}

fn linear_to_srgb(v: f64) -> f64 {
    let v = v.clamp(0.0, 1.0);
    if v <= 0.003_130_8 {
        v * 12.92
    } else {
        1.055 * v.powf(1.0 / 2.4) - 0.055
    }
}

/// Separable Gaussian blur of an interleaved f32 RGB image, edges clamped.
fn blur(img: &mut [f32], w: usize, h: usize, sigma: f64) {
    let radius = (3.0 * sigma).ceil() as isize;
    if radius < 1 {
        return;
    }
    let kernel: Vec<f32> =
        (-radius..=radius).map(|i| (-(i * i) as f64 / (2.0 * sigma * sigma)).exp() as f32).collect();
    let sum: f32 = kernel.iter().sum();
    let kernel: Vec<f32> = kernel.iter().map(|k| k / sum).collect();
    let mut tmp = vec![0f32; img.len()];
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0f32; 3];
            for (k, kv) in kernel.iter().enumerate() {
                let xx = (x as isize + k as isize - radius).clamp(0, w as isize - 1) as usize;
                let i = (y * w + xx) * 3;
                for c in 0..3 {
                    acc[c] += kv * img[i + c];
                }
            }
            tmp[(y * w + x) * 3..][..3].copy_from_slice(&acc);
        }
    }
    for y in 0..h {
        for x in 0..w {
            let mut acc = [0f32; 3];
            for (k, kv) in kernel.iter().enumerate() {
                let yy = (y as isize + k as isize - radius).clamp(0, h as isize - 1) as usize;
                let i = (yy * w + x) * 3;
                for c in 0..3 {
                    acc[c] += kv * tmp[i + c];
                }
            }
            img[(y * w + x) * 3..][..3].copy_from_slice(&acc);
        }
    }
}

/// Applies white balance, vignetting, blur, sensor noise and JPEG re-encoding (in that order, as a camera
/// would) to an interleaved 8-bit sRGB image in place. `seed` draws the noise; the same inputs give the
/// same bytes.
///
/// # Errors
/// [`EffectsError`]: the noise σ is not a valid standard deviation, or the JPEG codec failed.
pub fn apply_camera_effects(
    rgb: &mut [u8],
    width: u32,
    height: u32,
    fx: &CameraEffects,
    seed: u64,
) -> Result<(), EffectsError> {
    if fx.is_none() {
        return Ok(());
    }
    let (w, h) = (width as usize, height as usize);
    let lut: Vec<f32> = (0..256).map(|v| srgb_to_linear(v as f64 / 255.0) as f32).collect();
    let mut img: Vec<f32> = rgb.iter().map(|&v| lut[v as usize]).collect();
    let gains = white_balance_gains(fx.white_balance_k).map(|g| g as f32);
    let (cx, cy) = (w as f64 / 2.0, h as f64 / 2.0);
    let r2_max = cx * cx + cy * cy;
    for y in 0..h {
        for x in 0..w {
            let (dx, dy) = (x as f64 + 0.5 - cx, y as f64 + 0.5 - cy);
            let v = (1.0 - fx.vignetting * (dx * dx + dy * dy) / r2_max) as f32;
            let i = (y * w + x) * 3;
            for c in 0..3 {
                img[i + c] *= gains[c] * v;
            }
        }
    }
    if fx.blur_sigma_px > 0.05 {
        blur(&mut img, w, h, fx.blur_sigma_px);
    }
    let mut rng = rand_chacha::ChaCha8Rng::seed_from_u64(seed);
    let normal = rand_distr::Normal::new(0.0f64, fx.noise_sigma.max(0.0))
        .map_err(|source| EffectsError::Noise { sigma: fx.noise_sigma, source })?;
    for (o, v) in rgb.iter_mut().zip(&img) {
        let s = linear_to_srgb(*v as f64) * 255.0;
        let n = if fx.noise_sigma > 0.0 { rng.sample(normal) } else { 0.0 };
        *o = (s + n).round().clamp(0.0, 255.0) as u8;
    }
    if let Some(q) = fx.jpeg_quality {
        let mut bytes = Vec::new();
        image::codecs::jpeg::JpegEncoder::new_with_quality(&mut bytes, q)
            .encode(rgb, width, height, image::ExtendedColorType::Rgb8)
            .map_err(|source| EffectsError::JpegEncode { quality: q, source })?;
        let decoded = image::load_from_memory_with_format(&bytes, image::ImageFormat::Jpeg)
            .map_err(EffectsError::JpegDecode)?
            .into_rgb8();
        rgb.copy_from_slice(decoded.as_raw());
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn solar_noon_at_the_equinox_is_ninety_minus_latitude_due_south() {
        // Day 80 (21 March): declination ≈ 0.
        let (az, el) = solar_position_deg(52.0, 80, 12.0);
        assert!((el - 38.0).abs() < 0.6, "{el}");
        assert!((az - 180.0).abs() < 1e-6, "{az}");
        // Southern hemisphere: the noon sun is due north.
        let (az, _) = solar_position_deg(-33.9, 80, 12.0);
        assert!(!(1e-6..=359.999).contains(&az), "{az}");
    }

    #[test]
    fn morning_sun_is_in_the_east_and_summer_noon_is_higher() {
        let (az, el) = solar_position_deg(35.7, 172, 8.0);
        assert!((45.0..135.0).contains(&az), "{az}");
        assert!(el > 20.0, "{el}");
        // 21 June noon at 35.7° N: 90 − 35.7 + 23.44 ≈ 77.7°.
        let (_, noon) = solar_position_deg(35.7, 172, 12.0);
        assert!((noon - 77.7).abs() < 0.6, "{noon}");
        // 21 December: 90 − 35.7 − 23.44 ≈ 30.9°.
        let (_, winter) = solar_position_deg(35.7, 355, 12.0);
        assert!((winter - 30.9).abs() < 0.6, "{winter}");
    }

    #[test]
    fn draws_depend_on_seed_and_name_only_and_respect_the_ranges() {
        let ranges = LookRanges::defaults(35.7);
        let a = FrameLook::draw(&ranges, 7, "f0001").unwrap();
        assert_eq!(a, FrameLook::draw(&ranges, 7, "f0001").unwrap());
        assert_ne!(a, FrameLook::draw(&ranges, 7, "f0002").unwrap());
        assert_ne!(a, FrameLook::draw(&ranges, 8, "f0001").unwrap());
        let mut skies = std::collections::BTreeMap::new();
        for i in 0..300 {
            let l = FrameLook::draw(&ranges, 1, &format!("f{i}")).unwrap();
            assert!(l.sun_elevation_deg >= 15.0 && l.sun_elevation_deg <= 90.0);
            let (day, hour) = (l.day_of_year.unwrap(), l.solar_time_h.unwrap());
            assert!((1..=365).contains(&day) && (7.0..18.0).contains(&hour));
            let (az, el) = solar_position_deg(35.7, day, hour);
            assert!((az - l.sun_azimuth_deg).abs() < 2e-3 && (el - l.sun_elevation_deg).abs() < 2e-3);
            assert!((5000.0..=7500.0).contains(&l.camera.white_balance_k));
            assert!(l.exposure_ev.abs() <= 0.3);
            *skies.entry(format!("{:?}", l.sky)).or_insert(0) += 1;
        }
        // 50/30/20 % over 300 draws: each within a wide binomial margin.
        assert!((110..190).contains(&skies["Clear"]), "{skies:?}");
        assert!((60..125).contains(&skies["Hazy"]), "{skies:?}");
        assert!((30..95).contains(&skies["Overcast"]), "{skies:?}");
    }

    #[test]
    fn plain_look_is_the_seeded_sun_without_effects() {
        let l = FrameLook::draw(&LookRanges::plain(10.0), 3, "any").unwrap();
        assert_eq!((l.sun_azimuth_deg, l.sun_elevation_deg), sun_from_seed(3));
        assert!(l.camera.is_none() && l.visibility_m.is_none() && l.sky == Sky::Clear);
    }

    #[test]
    fn an_impossible_sun_range_is_refused_in_words() {
        let mut r = LookRanges::defaults(80.0);
        r.sun = SunRange::Dates {
            latitude_deg: 80.0,
            days: [340, 365],
            solar_hours: [7.0, 18.0],
            min_elevation_deg: 15.0,
        };
        let e = FrameLook::draw(&r, 0, "f").unwrap_err().to_string();
        assert!(e.contains("does not rise") && e.contains("80.00"), "{e}");
        r.white_balance_k = [7000.0, 6000.0];
        assert!(r.check().unwrap_err().to_string().contains("white balance"));
    }

    #[test]
    fn white_balance_warms_or_cools_and_neutral_is_identity() {
        let n = white_balance_gains(6500.0);
        assert!(n.iter().all(|g| (g - 1.0).abs() < 1e-12), "{n:?}");
        // A camera set to a low temperature (expecting warm light) pushes a 6500 K scene to blue.
        let cool = white_balance_gains(4000.0);
        assert!(cool[2] > 1.1 && cool[0] < 0.95, "{cool:?}");
        let warm = white_balance_gains(9000.0);
        assert!(warm[0] > 1.03 && warm[2] < 0.97, "{warm:?}");
    }

    #[test]
    fn effects_are_deterministic_and_do_what_they_say() {
        let (w, h) = (64u32, 48u32);
        let grey = vec![128u8; (w * h * 3) as usize];
        // Vignetting only: centre unchanged, corners darker.
        let mut v = grey.clone();
        let fx = CameraEffects { vignetting: 0.3, ..CameraEffects::NONE };
        apply_camera_effects(&mut v, w, h, &fx, 1).unwrap();
        let px = |img: &[u8], x: u32, y: u32| img[((y * w + x) * 3) as usize];
        assert!(px(&v, 32, 24).abs_diff(128) <= 1);
        assert!(px(&v, 0, 0) < 110, "{}", px(&v, 0, 0));
        // Noise: same seed same bytes, other seed other bytes, mean kept.
        let fx = CameraEffects { noise_sigma: 2.0, ..CameraEffects::NONE };
        let (mut a, mut b, mut c) = (grey.clone(), grey.clone(), grey.clone());
        apply_camera_effects(&mut a, w, h, &fx, 5).unwrap();
        apply_camera_effects(&mut b, w, h, &fx, 5).unwrap();
        apply_camera_effects(&mut c, w, h, &fx, 6).unwrap();
        assert_eq!(a, b);
        assert_ne!(a, c);
        let mean = a.iter().map(|&v| v as f64).sum::<f64>() / a.len() as f64;
        let sd = (a.iter().map(|&v| (v as f64 - mean).powi(2)).sum::<f64>() / a.len() as f64).sqrt();
        assert!((mean - 128.0).abs() < 0.2 && (sd - 2.0).abs() < 0.3, "{mean} {sd}");
        // Blur spreads a white line; JPEG changes a sharp edge but keeps flat areas.
        let mut line = vec![0u8; (w * h * 3) as usize];
        for y in 0..h {
            line[((y * w + 32) * 3) as usize..][..3].fill(255);
        }
        let mut blurred = line.clone();
        apply_camera_effects(
            &mut blurred,
            w,
            h,
            &CameraEffects { blur_sigma_px: 1.0, ..CameraEffects::NONE },
            0,
        )
        .unwrap();
        assert!(px(&blurred, 33, 10) > 60 && px(&blurred, 32, 10) < 255);
        let mut j = line.clone();
        apply_camera_effects(
            &mut j,
            w,
            h,
            &CameraEffects { jpeg_quality: Some(50), ..CameraEffects::NONE },
            0,
        )
        .unwrap();
        assert_ne!(j, line);
        assert!(px(&j, 5, 10) < 20 && px(&j, 32, 10) > 180);
    }
}
