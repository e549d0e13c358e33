//! Range sensors: beam tables, mounts and rates, with presets for the paper's
//! ERIM scanner and for spinning lidars, and rendering of what a sensor sees
//! of any [`RayCast`] scene.

use std::ops::Range;

use arcnav_vehicle::config::{self, ConfigError};
use arcnav_vehicle::frames::isometry_from_xyz_rpy;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{Isometry, Utime};
use nalgebra::{Point3, Vector3};
use serde::{Deserialize, Serialize};

use crate::image::{BeamTable, RangeImage};
use crate::raycast::RayCast;

/// Which sensor. Lives in `[sensor]`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum SensorPreset {
    /// The paper's ERIM laser scanner: 64×256, 0.5° per pixel, 2 Hz, roof
    /// mounted and tilted down (002 §2, §4).
    Erim,
    /// A 64-beam spinning lidar: +2° … -24.9°, 2048 columns over 360°, 10 Hz.
    Lidar64,
    /// A 128-beam spinning lidar: ±22.5°, 2048 columns over 360°, 10 Hz.
    Lidar128,
    /// A depth camera: 320×240 over 45° × 33.75°, 30 Hz, 10 m, on the roof
    /// pitched 25° down (paper 000's cameras at QVGA; see
    /// [`SensorModel::depth_camera`]).
    #[serde(rename = "depth_camera")]
    DepthCamera,
    /// The `[sensor.custom]` table.
    Custom,
}

/// The longest sensor id: it names a channel, `RANGE_IMAGE_<ID>`.
pub const MAX_SENSOR_ID_LEN: usize = 64;

/// The largest range image as a message, bytes: what LCM carries in one
/// message and one log event (2^28).
pub const MAX_IMAGE_BYTES: usize = 1 << 28;

/// A sensor described field by field (`preset = "custom"`). The defaults
/// are the ERIM preset's values.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CustomSensorConfig {
    pub id: String,
    pub rows: usize,
    pub cols: usize,
    /// Elevation of the first row's beam edge, degrees, sensor frame.
    pub elevation_top_deg: f64,
    /// Elevation of the last row's beam edge, degrees.
    pub elevation_bottom_deg: f64,
    /// Azimuth of the first column's edge, degrees, + left.
    pub azimuth_left_deg: f64,
    /// Azimuth of the last column's edge, degrees.
    pub azimuth_right_deg: f64,
    pub rate_hz: f64,
    pub max_range_m: f64,
    /// From an image's (or a slice's) time stamp to its cells in the local
    /// map: the acquisition the stamp does not cover and perception's
    /// processing, s (`[pipeline] perception_latency_s = "auto"` takes the
    /// slowest sensor's).
    pub latency_s: f64,
    /// Sensor origin in the vehicle frame, m.
    pub mount_position_m: [f64; 3],
    /// Sensor → vehicle roll, pitch (+ down), yaw, degrees.
    pub mount_rpy_deg: [f64; 3],
}

impl Default for CustomSensorConfig {
    fn default() -> Self {
        SensorModel::erim().to_custom()
    }
}

/// A sensor arcnav sees with: `[sensor]`, or each of `[[sensors]]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct SensorConfig {
    pub preset: SensorPreset,
    /// Used when `preset = "custom"`.
    pub custom: CustomSensorConfig,
    /// The sensor's id (names its channel, `RANGE_IMAGE_<ID>`), instead of
    /// the preset's: two sensors of one preset need two ids.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub id: Option<String>,
    /// Where it is mounted, instead of the preset's: origin in the vehicle
    /// frame, m, and roll, pitch (+ down), yaw, degrees.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_position_m: Option<[f64; 3]>,
    #[serde(skip_serializing_if = "Option::is_none")]
    pub mount_rpy_deg: Option<[f64; 3]>,
    /// Images per second, instead of the preset's.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub rate_hz: Option<f64>,
    /// Capture to cells, instead of the preset's, s.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub latency_s: Option<f64>,
}

impl Default for SensorConfig {
    fn default() -> Self {
        Self {
            preset: SensorPreset::Erim,
            custom: CustomSensorConfig::default(),
            id: None,
            mount_position_m: None,
            mount_rpy_deg: None,
            rate_hz: None,
            latency_s: None,
        }
    }
}

/// Checks a sensor id: letters, digits or _, at most [`MAX_SENSOR_ID_LEN`].
fn check_id(key: &str, id: &str) -> Result<(), ConfigError> {
    if id.is_empty() || !id.chars().all(|ch| ch.is_ascii_alphanumeric() || ch == '_') {
        return Err(ConfigError::new(
            key,
            format!("{id:?} must be letters, digits or _"),
        ));
    }
    if id.len() > MAX_SENSOR_ID_LEN {
        return Err(ConfigError::new(
            key,
            format!(
                "is {} characters long, must be at most {MAX_SENSOR_ID_LEN} (it names the channel RANGE_IMAGE_<ID>)",
                id.len()
            ),
        ));
    }
    Ok(())
}

impl SensorConfig {
    /// The preset's name as in the configuration.
    pub fn preset_name(&self) -> &'static str {
        match self.preset {
            SensorPreset::Erim => "erim",
            SensorPreset::Lidar64 => "lidar64",
            SensorPreset::Lidar128 => "lidar128",
            SensorPreset::DepthCamera => "depth_camera",
            SensorPreset::Custom => "custom",
        }
    }

    /// Keys relative to `[sensor]`.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let c = &self.custom;
        let key = |k: &str| format!("custom.{k}");
        check_id(&key("id"), &c.id)?;
        if let Some(id) = &self.id {
            check_id("id", id)?;
        }
        if let Some(rate) = self.rate_hz {
            config::positive("rate_hz", rate)?;
        }
        if let Some(latency) = self.latency_s {
            config::in_range("latency_s", latency, 0.0, 10.0)?;
        }
        for (k, values) in [
            ("mount_position_m", self.mount_position_m),
            ("mount_rpy_deg", self.mount_rpy_deg),
        ] {
            if values.is_some_and(|v| v.iter().any(|x| !x.is_finite())) {
                return Err(ConfigError::new(k, "holds a value that is not finite"));
            }
        }
        if !(1..=4096).contains(&c.rows) {
            return Err(ConfigError::new(
                key("rows"),
                format!("is {}, must be 1 to 4096", c.rows),
            ));
        }
        if !(1..=65_536).contains(&c.cols) {
            return Err(ConfigError::new(
                key("cols"),
                format!("is {}, must be 1 to 65536", c.cols),
            ));
        }
        // ranges, then elevations and azimuths, 4 bytes each; the rest is small.
        let bytes = 4 * (c.rows * c.cols + c.rows + c.cols) + 256;
        if bytes > MAX_IMAGE_BYTES {
            return Err(ConfigError::new(
                key("cols"),
                format!(
                    "a {}×{} image is {:.1} MiB as a message; an LCM message and a log event hold at most {} MiB",
                    c.rows,
                    c.cols,
                    bytes as f64 / f64::from(1 << 20),
                    MAX_IMAGE_BYTES >> 20
                ),
            ));
        }
        config::in_range(&key("elevation_top_deg"), c.elevation_top_deg, -90.0, 90.0)?;
        config::in_range(
            &key("elevation_bottom_deg"),
            c.elevation_bottom_deg,
            -90.0,
            90.0,
        )?;
        if c.elevation_bottom_deg >= c.elevation_top_deg {
            return Err(ConfigError::new(
                key("elevation_bottom_deg"),
                format!(
                    "is {}°, must be below elevation_top_deg ({}°)",
                    c.elevation_bottom_deg, c.elevation_top_deg
                ),
            ));
        }
        config::in_range(&key("azimuth_left_deg"), c.azimuth_left_deg, -360.0, 360.0)?;
        config::in_range(
            &key("azimuth_right_deg"),
            c.azimuth_right_deg,
            -360.0,
            360.0,
        )?;
        if (c.azimuth_left_deg - c.azimuth_right_deg).abs() > 360.0 {
            return Err(ConfigError::new(
                key("azimuth_right_deg"),
                "the azimuth span exceeds 360°",
            ));
        }
        config::positive(&key("rate_hz"), c.rate_hz)?;
        config::positive(&key("max_range_m"), c.max_range_m)?;
        config::in_range(&key("latency_s"), c.latency_s, 0.0, 10.0)?;
        for (i, v) in c
            .mount_position_m
            .iter()
            .chain(&c.mount_rpy_deg)
            .enumerate()
        {
            if !v.is_finite() {
                let k = if i < 3 {
                    "mount_position_m"
                } else {
                    "mount_rpy_deg"
                };
                return Err(ConfigError::new(key(k), "holds a value that is not finite"));
            }
        }
        Ok(())
    }

    /// The sensor this configuration describes: the preset (or `custom`)
    /// with the id, mount and rate given here instead of its own.
    pub fn model(&self) -> Result<SensorModel, ConfigError> {
        self.validate()?;
        let preset = match self.preset {
            SensorPreset::Erim => SensorModel::erim(),
            SensorPreset::Lidar64 => SensorModel::lidar64(),
            SensorPreset::Lidar128 => SensorModel::lidar128(),
            SensorPreset::DepthCamera => SensorModel::depth_camera(),
            SensorPreset::Custom => {
                return Ok(SensorModel::from_custom(
                    &self.with_overrides(self.custom.clone()),
                ));
            }
        };
        if self.id.is_none()
            && self.mount_position_m.is_none()
            && self.mount_rpy_deg.is_none()
            && self.rate_hz.is_none()
            && self.latency_s.is_none()
        {
            return Ok(preset);
        }
        Ok(SensorModel::from_custom(
            &self.with_overrides(preset.to_custom()),
        ))
    }

    fn with_overrides(&self, mut c: CustomSensorConfig) -> CustomSensorConfig {
        if let Some(id) = &self.id {
            c.id.clone_from(id);
        }
        if let Some(m) = self.mount_position_m {
            c.mount_position_m = m;
        }
        if let Some(m) = self.mount_rpy_deg {
            c.mount_rpy_deg = m;
        }
        if let Some(r) = self.rate_hz {
            c.rate_hz = r;
        }
        if let Some(l) = self.latency_s {
            c.latency_s = l;
        }
        c
    }
}

/// A range sensor: its beams, where it is mounted and how often it images.
#[derive(Debug, Clone, PartialEq)]
pub struct SensorModel {
    pub id: String,
    pub beams: BeamTable,
    /// Sensor → vehicle.
    pub vehicle_from_sensor: Isometry,
    pub rate_hz: f64,
    /// Returns beyond this are not reported, m.
    pub max_range_m: f64,
    /// Capture to cells in the local map, s (see
    /// [`CustomSensorConfig::latency_s`]).
    pub latency_s: f64,
    custom: CustomSensorConfig,
}

impl SensorModel {
    /// Builds a model from explicit values.
    pub fn from_custom(c: &CustomSensorConfig) -> Self {
        let rad = f64::to_radians;
        Self {
            id: c.id.clone(),
            beams: BeamTable::uniform(
                c.rows,
                c.cols,
                rad(c.elevation_top_deg),
                rad(c.elevation_bottom_deg),
                rad(c.azimuth_left_deg),
                rad(c.azimuth_right_deg),
            ),
            vehicle_from_sensor: isometry_from_xyz_rpy(
                c.mount_position_m,
                rad(c.mount_rpy_deg[0]),
                rad(c.mount_rpy_deg[1]),
                rad(c.mount_rpy_deg[2]),
            ),
            rate_hz: c.rate_hz,
            max_range_m: c.max_range_m,
            latency_s: c.latency_s,
            custom: c.clone(),
        }
    }

    /// The paper's ERIM: 64×256 pixels of 0.5° (32° × 128°), 2 Hz, 2.2 m up
    /// on the roof above the front axle, pitched 18° down so its rows look
    /// from ~3 m in front of the bumper to beyond the 20 m map window.
    pub fn erim() -> Self {
        Self::from_custom(&CustomSensorConfig {
            id: "erim".into(),
            rows: 64,
            cols: 256,
            elevation_top_deg: 16.0,
            elevation_bottom_deg: -16.0,
            azimuth_left_deg: 64.0,
            azimuth_right_deg: -64.0,
            rate_hz: 2.0,
            max_range_m: 40.0,
            // The frame's scan and 1993's processing (002 §5 saw ~0.6 s
            // from image to map).
            latency_s: 0.3,
            mount_position_m: [1.5, 0.0, 2.2],
            mount_rpy_deg: [0.0, 18.0, 0.0],
        })
    }

    /// A 64-beam spinning lidar (HDL-64E-like vertical table), 2048 × 360°, 10 Hz.
    pub fn lidar64() -> Self {
        Self::from_custom(&CustomSensorConfig {
            id: "lidar64".into(),
            rows: 64,
            cols: 2048,
            elevation_top_deg: 2.0,
            elevation_bottom_deg: -24.9,
            azimuth_left_deg: 180.0,
            azimuth_right_deg: -180.0,
            rate_hz: 10.0,
            max_range_m: 100.0,
            // A rotation (0.1 s) and perception's processing: 6-10 ms a
            // frame measured (`arcnav sim` stage times), 50 ms allowed.
            latency_s: 0.15,
            mount_position_m: [1.2, 0.0, 2.4],
            mount_rpy_deg: [0.0, 0.0, 0.0],
        })
    }

    /// A 128-beam spinning lidar (±22.5°), 2048 × 360°, 10 Hz.
    pub fn lidar128() -> Self {
        Self::from_custom(&CustomSensorConfig {
            id: "lidar128".into(),
            rows: 128,
            cols: 2048,
            elevation_top_deg: 22.5,
            elevation_bottom_deg: -22.5,
            ..Self::lidar64().custom
        })
    }

    /// A depth camera at QVGA, as paper 000's eight were run (320×240 of
    /// its 45°-wide Xtion), 30 Hz, returns to 10 m, 2.2 m up above the
    /// front axle and pitched 25° down (its rows look from 2.3 m ahead of
    /// the mount to the horizon).
    ///
    /// Beam tables here are separable (an elevation per row, an azimuth
    /// per column), so the camera is modelled with equal angles per pixel
    /// rather than a pinhole's equal steps on the image plane: the same
    /// field of view and resolution, its rays within 1.3° of a pinhole's
    /// at the corners and exact along the centre row and column. Ranges
    /// are distances along the ray, not depths along the optical axis.
    pub fn depth_camera() -> Self {
        Self::from_custom(&CustomSensorConfig {
            id: "depth_camera".into(),
            rows: 240,
            cols: 320,
            elevation_top_deg: 16.875,
            elevation_bottom_deg: -16.875,
            azimuth_left_deg: 22.5,
            azimuth_right_deg: -22.5,
            rate_hz: 30.0,
            max_range_m: 10.0,
            // A frame (33 ms) and 50 ms of processing.
            latency_s: 0.08,
            mount_position_m: [1.5, 0.0, 2.2],
            mount_rpy_deg: [0.0, 25.0, 0.0],
        })
    }

    /// The explicit values of this model (as `[sensor.custom]` would hold them).
    pub fn to_custom(&self) -> CustomSensorConfig {
        self.custom.clone()
    }

    /// Time between images, µs.
    pub fn period_us(&self) -> Utime {
        seconds_to_micros(1.0 / self.rate_hz)
    }

    /// An empty image of this sensor's shape (every range NaN).
    pub fn blank_image(&self, utime: Utime) -> RangeImage {
        RangeImage {
            utime,
            sensor: self.id.clone(),
            vehicle_from_sensor: self.vehicle_from_sensor,
            beams: self.beams.clone(),
            range: vec![f32::NAN; self.beams.rows() * self.beams.cols()],
        }
    }

    /// The image this sensor takes of `scene` from `world_from_vehicle`.
    pub fn render(
        &self,
        utime: Utime,
        world_from_vehicle: &Isometry,
        scene: &impl RayCast,
    ) -> RangeImage {
        let mut image = self.blank_image(utime);
        self.render_rows(
            world_from_vehicle,
            scene,
            0..self.beams.rows(),
            &mut image.range,
        );
        image
    }

    /// Renders rows `rows` into `out` (`rows.len() × cols` values, row-major),
    /// so callers can split an image between threads. No return = NaN.
    pub fn render_rows(
        &self,
        world_from_vehicle: &Isometry,
        scene: &impl RayCast,
        rows: Range<usize>,
        out: &mut [f32],
    ) {
        self.render_rows_posed(&self.posed_beams(world_from_vehicle), scene, rows, out);
    }

    /// The beams with the vehicle at `world_from_vehicle`, for
    /// [`render_rows_posed`](Self::render_rows_posed): computed once a
    /// frame by a caller that renders it in many parts.
    pub fn posed_beams(&self, world_from_vehicle: &Isometry) -> PosedBeams {
        let world_from_sensor = world_from_vehicle * self.vehicle_from_sensor;
        let rotation = world_from_sensor.rotation.to_rotation_matrix();
        PosedBeams {
            origin: Point3::from(world_from_sensor.translation.vector),
            across: self
                .beams
                .azimuth
                .iter()
                .map(|&az| {
                    let (sin_az, cos_az) = f64::from(az).sin_cos();
                    rotation * Vector3::new(cos_az, sin_az, 0.0)
                })
                .collect(),
            up: rotation * Vector3::z(),
        }
    }

    /// [`render_rows`](Self::render_rows) with the beams posed (as
    /// [`posed_beams`](Self::posed_beams) poses them).
    pub fn render_rows_posed(
        &self,
        beams: &PosedBeams,
        scene: &impl RayCast,
        rows: Range<usize>,
        out: &mut [f32],
    ) {
        let cols = self.beams.cols();
        let mut directions = Vec::with_capacity(cols);
        for (row, chunk) in rows.zip(out.chunks_mut(cols)) {
            let Some(&el) = self.beams.elevation.get(row) else {
                break;
            };
            let (sin_el, cos_el) = f64::from(el).sin_cos();
            let lift = beams.up * sin_el;
            directions.clear();
            directions.extend(beams.across.iter().map(|a| a * cos_el + lift));
            scene.cast_each(&beams.origin, &directions, self.max_range_m, chunk);
        }
    }
}

/// A sensor's beams with the vehicle at one pose, in the world. Beams are
/// separable: R·(cos el cos az, cos el sin az, sin el) =
/// cos el · R·(cos az, sin az, 0) + sin el · R·z, so per column the first
/// factor is kept, and R·z once.
#[derive(Debug, Clone)]
pub struct PosedBeams {
    /// Where every beam starts.
    origin: Point3<f64>,
    /// Per column, R·(cos az, sin az, 0).
    across: Vec<Vector3<f64>>,
    /// R·z.
    up: Vector3<f64>,
}

impl PosedBeams {
    /// Where every beam starts, in the world.
    pub fn origin(&self) -> Point3<f64> {
        self.origin
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use approx::assert_relative_eq;

    #[test]
    fn the_erim_preset_is_the_papers_scanner() {
        let erim = SensorModel::erim();
        assert_eq!((erim.beams.rows(), erim.beams.cols()), (64, 256));
        assert_eq!(erim.rate_hz, 2.0);
        assert_eq!(erim.period_us(), 500_000);
        // 0.5° per pixel in both directions.
        let el = &erim.beams.elevation;
        assert_relative_eq!(
            f64::from(el[0] - el[1]),
            0.5f64.to_radians(),
            epsilon = 1e-6
        );
        let az = &erim.beams.azimuth;
        assert_relative_eq!(
            f64::from(az[0] - az[1]),
            0.5f64.to_radians(),
            epsilon = 1e-6
        );
        // Tilted down: the top row looks 2° below the horizon.
        let top = erim.vehicle_from_sensor.rotation
            * Vector3::from(erim.beams.direction(0, 128).unwrap());
        assert_relative_eq!(top.z.asin().to_degrees(), -2.25, epsilon = 0.3);
    }

    #[test]
    fn lidar_presets_cover_360_degrees_at_10_hz() {
        for lidar in [SensorModel::lidar64(), SensorModel::lidar128()] {
            assert_eq!(lidar.beams.cols(), 2048);
            assert_eq!(lidar.rate_hz, 10.0);
            let span = lidar.beams.azimuth[0] - lidar.beams.azimuth[2047];
            assert_relative_eq!(
                f64::from(span),
                std::f64::consts::TAU * 2047.0 / 2048.0,
                epsilon = 1e-5
            );
        }
        assert_eq!(SensorModel::lidar64().beams.rows(), 64);
        assert_eq!(SensorModel::lidar128().beams.rows(), 128);
    }

    #[test]
    fn config_selects_presets_and_checks_custom_values() {
        let config = SensorConfig {
            preset: SensorPreset::Lidar128,
            ..Default::default()
        };
        assert_eq!(config.model().unwrap().id, "lidar128");
        let mut config = SensorConfig {
            preset: SensorPreset::Custom,
            ..Default::default()
        };
        config.custom.rows = 16;
        assert_eq!(config.model().unwrap().beams.rows(), 16);
        config.custom.elevation_bottom_deg = 30.0;
        assert_eq!(
            config.validate().unwrap_err().key,
            "custom.elevation_bottom_deg"
        );
        assert_eq!(
            SensorConfig::default().custom,
            SensorModel::erim().to_custom()
        );
    }

    #[test]
    fn a_sensor_larger_than_a_message_can_carry_or_with_a_long_id_is_refused_at_validation() {
        let mut config = SensorConfig {
            preset: SensorPreset::Custom,
            ..Default::default()
        };
        config.custom.rows = 4096;
        config.custom.cols = 65_536;
        let err = config.validate().unwrap_err();
        assert_eq!(err.key, "custom.cols");
        assert!(
            err.reason.contains("4096×65536 image is 1024.3 MiB"),
            "{}",
            err.reason
        );
        // 128 × 2048 (a 128-beam lidar) is far inside.
        config.custom.rows = 128;
        config.custom.cols = 2048;
        assert!(config.validate().is_ok());
        config.custom.id = "x".repeat(990);
        let err = config.validate().unwrap_err();
        assert_eq!(err.key, "custom.id");
        assert!(err.reason.contains("990 characters"), "{}", err.reason);
    }
}
