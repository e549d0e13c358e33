//! # arcnav-perception
//!
//! Early traversability evaluation (002 §4): each range image, on its own,
//! becomes the list of untraversable cells it shows (world frame) plus the
//! ground footprint it observed. Nothing is interpolated and no two images
//! are merged: remembering is the local map's job.
//!
//! - [`image`]: range images and beam tables;
//! - [`sensor`]: sensor models (ERIM, 64- and 128-beam lidars, custom) and
//!   rendering of any [`raycast::RayCast`] scene;
//! - [`evaluator`]: the [`TerrainEvaluator`] trait and its output;
//! - [`cells`]: the paper's per-cell classifier;
//! - [`height_diff`]: 000's multi-scale height differences, with
//!   [`median`] outlier filtering;
//! - [`pca`]: 001's hierarchical PCA and roughness;
//! - [`registry`]: evaluators by name, and the plug-in trait;
//! - [`evidence`]: hole evidence accumulated over images (the one
//!   stateful judgement every evaluator shares);
//! - [`fov`]: the observed footprint polygon;
//! - [`shadow`]: the ground in it the image did not see;
//! - [`stream`]: range images arriving in slices, judged as they come
//!   (002 §7's integrated mode);
//! - [`scene`]: analytic scenes for tests and benchmarks;
//! - [`config`]: `[perception]` and the evaluator registry.

pub mod cells;
pub mod config;
pub mod evaluator;
pub mod evidence;
pub mod fov;
mod grid;
pub mod height_diff;
pub mod heights;
pub mod image;
pub mod median;
pub mod pca;
pub mod plugin;
pub mod raycast;
pub mod registry;
pub mod scene;
pub mod sensor;
pub mod shadow;
pub mod stream;
mod window;

pub use cells::CellClassifier;
pub use config::{
    CellsConfig, DropOffConfig, EvidenceConfig, HeightsConfig, PerceptionConfig, RegionConfig,
    StreamingConfig,
};
pub use evaluator::{
    HeightSample, ImageStats, InOrder, ObstacleCell, ObstacleReport, PerceptionError, Reasons,
    Region, Runner, Support, TerrainEvaluator, suspected_drop_off,
};
pub use evidence::{EvidenceStats, HoleEvidence};
pub use fov::FovPolygon;
pub use height_diff::{HeightDiff, HeightDiffConfig, HeightDiffMaps};
pub use heights::HeightSampler;
pub use image::{BeamTable, ImageError, RangeImage};
pub use pca::{HierarchicalPca, PcaConfig, PcaMaps};
pub use plugin::EvaluatorPlugin;
pub use raycast::RayCast;
pub use registry::EvaluatorRegistry;
pub use sensor::{PosedBeams, SensorConfig, SensorModel, SensorPreset};
pub use shadow::{Shadow, ShadowIndex, Shadows};
pub use stream::{FrameStream, RangeSlice, SliceAxis, SliceError, StreamCounts};

/// Whether this processor can run the AVX2 paths a test compares with the
/// portable ones. Under `CI=true` a processor without AVX2 fails the test
/// (the comparison would be skipped unseen); elsewhere it is said and the
/// comparison skipped.
#[cfg(all(test, target_arch = "x86_64"))]
pub(crate) fn avx2_to_test(what: &str) -> bool {
    if std::arch::is_x86_feature_detected!("avx2") {
        return true;
    }
    assert!(
        std::env::var("CI").as_deref() != Ok("true"),
        "CI's machine has no AVX2: {what} is untested"
    );
    eprintln!("no AVX2 on this processor: {what} not compared");
    false
}
