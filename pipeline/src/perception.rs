//! Perception: range images and poses in, obstacle reports out (002 §4,
//! *early traversability evaluation*: every image is judged on its own, with
//! the pose at its capture time).

use std::collections::VecDeque;

use arcnav_perception::{
    EvidenceStats, FrameStream, HeightSampler, HoleEvidence, ImageStats, InOrder, ObstacleReport,
    PerceptionConfig, RangeImage, RangeSlice, Runner, StreamCounts, StreamingConfig,
    TerrainEvaluator,
};
use arcnav_vehicle::config::ConfigError;
use arcnav_vehicle::time::seconds_to_micros;
use arcnav_vehicle::{Pose, PoseHistory, Utime};
use serde::Serialize;

use crate::config::PipelineConfig;

/// The most poses kept, whatever `pipeline.pose_history_s` says: 600 s (its
/// largest value) of a 100 Hz stream, or 60 s of a 1 kHz one (~10 MB).
const MAX_POSES: usize = 100_000;

/// Why an image produced no report.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct PerceptionDrops {
    /// No pose around its capture time (too old for the history, or no pose
    /// arrived in time).
    pub no_pose: u64,
    /// The evaluator refused it (malformed image).
    pub invalid: u64,
    /// Older than an image already evaluated from the same sensor.
    pub out_of_order: u64,
    /// Waiting for their pose when the pose clock went backwards (a log
    /// that starts over): their poses will never come.
    pub clock_restart: u64,
    /// From a sensor past the first [`MAX_SENSORS`] ids seen (the local
    /// map tracks at most that many): each sensor's frames and capture
    /// times are kept, so their number is bounded.
    pub too_many_sensors: u64,
}

impl PerceptionDrops {
    /// Every image and slice dropped, whatever the reason.
    pub fn total(&self) -> u64 {
        self.no_pose + self.invalid + self.out_of_order + self.clock_restart + self.too_many_sensors
    }
}

/// The most sensors perception keeps state for: the local map's limit.
pub use arcnav_localmap::MAX_SENSORS;

/// Images judged together (`perception.fuse_within_s`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct FusionCounts {
    /// Evaluations of more than one image (one height map each).
    pub evaluations: u64,
    /// Images judged in them.
    pub images: u64,
}

impl FusionCounts {
    /// Images per fused evaluation (0 when none was).
    pub fn images_per_evaluation(&self) -> f64 {
        if self.evaluations == 0 {
            0.0
        } else {
            self.images as f64 / self.evaluations as f64
        }
    }
}

/// A range image or a slice of one, waiting for its pose.
#[derive(Debug)]
enum Pending {
    Image(RangeImage),
    Slice(RangeSlice),
}

impl Pending {
    /// The newest pose it needs before it is judged: an image's at its
    /// capture time; a slice's at its last line, less what may be
    /// extrapolated.
    fn due(&self, extrapolation_us: Utime) -> Utime {
        match self {
            Pending::Image(image) => image.utime,
            Pending::Slice(slice) => slice.utime.saturating_sub(extrapolation_us),
        }
    }
}

/// What streamed slices did, summed over sensors.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub struct SliceCounts {
    /// Slices received (also counted in `images`' drops when dropped).
    pub received: u64,
    /// Slices refused by perception (malformed; inconsistent with their frame).
    pub invalid: u64,
    pub stream: StreamCounts,
}

/// What the hole evidence (`[perception.evidence]`) found over a run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EvidenceTotals {
    /// Images (or slices) it judged.
    pub images: u64,
    /// Near edges suspected, summed over images.
    pub suspected: u64,
    /// Gaps that dipped and rose as a hole's would.
    pub candidates: u64,
    /// Stretches of columns left unverified (reported as shadows), summed
    /// over images.
    pub unverified: u64,
}

impl EvidenceTotals {
    fn add(&mut self, found: EvidenceStats) {
        self.images += 1;
        self.suspected += u64::from(found.suspected);
        self.candidates += u64::from(found.candidates);
        self.unverified += u64::from(found.unverified);
    }
}

/// Perception: range images + poses → obstacle reports.
pub struct PerceptionNode {
    evaluator: Box<dyn TerrainEvaluator>,
    heights: HeightSampler,
    runner: Box<dyn Runner + Send>,
    poses: PoseHistory,
    waiting: VecDeque<Pending>,
    streaming: StreamingConfig,
    perception_config: PerceptionConfig,
    /// One assembler per sensor streaming slices.
    streams: Vec<(String, FrameStream)>,
    /// The sensor ids seen, at most [`MAX_SENSORS`].
    sensors: Vec<String>,
    /// Heights sampled from slices, and the holes the evidence suspected
    /// in them, not yet sent with a report.
    pending: ObstacleReport,
    /// Hole evidence over images (`[perception.evidence]`).
    evidence: HoleEvidence,
    /// What it suspected, over the run.
    pub evidence_totals: EvidenceTotals,
    pub slices: SliceCounts,
    max_waiting: usize,
    max_gap_us: Utime,
    extrapolation_us: Utime,
    newest_capture: Vec<(String, Utime)>,
    pub images: u64,
    pub reports: u64,
    pub drops: PerceptionDrops,
    pub totals: ImageStats,
    /// Images that arrived more than [`LATE_US`] after their capture time
    /// on the pose clock (still evaluated), and the latest of them, µs.
    pub late: u64,
    pub max_lateness_us: Utime,
    /// `perception.fuse_within_s`, µs (0: each image alone).
    fuse_within_us: Utime,
    pub fused: FusionCounts,
}

/// An image this long behind the newest pose has arrived late: the vehicle
/// drove on without its cells (a feed out of time order, say), µs.
pub const LATE_US: Utime = 1_000_000;

impl PerceptionNode {
    /// Built from `[perception]` and the pipeline timing (how long poses
    /// are kept, how many images may wait for theirs, the largest hole in
    /// the pose stream an image may be placed across). Errors name keys
    /// relative to `[perception]`.
    pub fn new(
        perception: &PerceptionConfig,
        timing: &PipelineConfig,
    ) -> Result<Self, ConfigError> {
        Ok(Self {
            evaluator: perception.build_evaluator()?,
            heights: HeightSampler::new(
                &perception.heights,
                &perception.region,
                perception.min_range_m,
                perception.max_range_m,
            ),
            runner: Box::new(InOrder),
            poses: PoseHistory::spanning(seconds_to_micros(timing.pose_history_s), MAX_POSES),
            waiting: VecDeque::new(),
            streaming: perception.streaming,
            perception_config: perception.clone(),
            streams: Vec::new(),
            sensors: Vec::new(),
            pending: ObstacleReport::default(),
            evidence: HoleEvidence::new(perception),
            evidence_totals: EvidenceTotals::default(),
            slices: SliceCounts::default(),
            max_waiting: timing.max_waiting_images,
            max_gap_us: seconds_to_micros(timing.max_pose_gap_s),
            extrapolation_us: seconds_to_micros(timing.slice_pose_extrapolation_s),
            newest_capture: Vec::new(),
            images: 0,
            reports: 0,
            drops: PerceptionDrops::default(),
            totals: ImageStats::default(),
            late: 0,
            max_lateness_us: 0,
            fuse_within_us: seconds_to_micros(perception.fuse_within_s),
            fused: FusionCounts::default(),
        })
    }

    /// A pose; images waiting for it are evaluated (reports handed to `out`).
    pub fn on_pose(&mut self, pose: &Pose, out: &mut dyn FnMut(ObstacleReport)) {
        if let Err(e) = self.poses.push(*pose) {
            tracing::debug!(%e, "pose not added to the perception history");
            if matches!(e, arcnav_vehicle::PoseHistoryError::NotIncreasing { .. })
                && pose.utime < self.newest_pose()
            {
                // Time went backwards (a log started over): start over.
                self.poses.clear();
                self.drops.clock_restart += self.waiting.len() as u64;
                self.waiting.clear();
                self.newest_capture.clear();
                self.streams.clear();
                self.sensors.clear();
                let _ = self.poses.push(*pose);
            }
        }
        self.drain(out);
    }

    /// Hands independent parts of each evaluation to `runner` (threads of a
    /// live executor); results are the same as without.
    /// The configuration it was built from.
    pub fn config(&self) -> &PerceptionConfig {
        &self.perception_config
    }

    pub fn set_runner(&mut self, runner: Box<dyn Runner + Send>) {
        self.runner = runner;
    }

    /// Images waiting for the pose at their capture time.
    pub fn waiting(&self) -> usize {
        self.waiting.len()
    }

    /// Slices stand in for images in the waiting room: as many as make up
    /// `max_waiting_images` of the largest streamed frame seen.
    fn slices_per_image(&self) -> usize {
        if self.waiting.iter().any(|p| matches!(p, Pending::Slice(_))) {
            self.waiting
                .iter()
                .filter_map(|p| match p {
                    Pending::Slice(s) => Some(s.frame_rows.max(s.frame_cols) / s.lines().max(1)),
                    Pending::Image(_) => None,
                })
                .max()
                .unwrap_or(1)
                .clamp(1, 4096)
        } else {
            1
        }
    }

    fn newest_pose(&self) -> Utime {
        self.poses.newest().map_or(Utime::MIN, |p| p.utime)
    }

    /// A range image; evaluated as soon as the pose at its capture time is known.
    pub fn on_image(&mut self, image: RangeImage, out: &mut dyn FnMut(ObstacleReport)) {
        self.images += 1;
        let lateness = self.newest_pose().saturating_sub(image.utime);
        if lateness > LATE_US {
            self.late += 1;
            self.max_lateness_us = self.max_lateness_us.max(lateness);
            if self.late.is_power_of_two() {
                tracing::warn!(
                    late = self.late,
                    sensor = %image.sensor,
                    "a range image arrived {:.2} s after its capture time (the pose clock had \
                     moved on): is the feed out of time order, e.g. a log not sorted by time?",
                    lateness as f64 * 1e-6
                );
            }
        }
        self.waiting.push_back(Pending::Image(image));
        self.drain(out);
    }

    /// A slice of a range image (002 §7's integrated mode): judged as soon
    /// as the pose when its last line was acquired is known; the cells it
    /// completes are reported at once (see [`arcnav_perception::stream`]).
    pub fn on_slice(&mut self, slice: RangeSlice, out: &mut dyn FnMut(ObstacleReport)) {
        self.slices.received += 1;
        if let Err(e) = slice.validate() {
            tracing::warn!(%e, sensor = %slice.sensor, "range slice refused");
            self.slices.invalid += 1;
            return;
        }
        self.waiting.push_back(Pending::Slice(slice));
        self.drain(out);
    }

    /// Ends every frame being streamed (its last slices will not come:
    /// the end of a log). Their cells not yet reported are.
    pub fn flush(&mut self, out: &mut dyn FnMut(ObstacleReport)) {
        let mut streams = std::mem::take(&mut self.streams);
        let (poses, max_gap, newest) = (&self.poses, self.max_gap_us, self.poses.newest().copied());
        let pose_at = |t: Utime| Self::pose_at(poses, newest, max_gap, t);
        let mut results = Vec::new();
        for (_, stream) in &mut streams {
            results.push(stream.flush(
                &pose_at,
                self.evaluator.as_mut(),
                &*self.runner,
                &mut |report| Self::send(&mut self.pending, &mut self.reports, report, out),
            ));
        }
        self.streams = streams;
        for result in results {
            self.account(result);
        }
        self.refresh_stream_counts();
    }

    /// Counts of every sensor's stream.
    fn refresh_stream_counts(&mut self) {
        let mut total = StreamCounts::default();
        for (_, stream) in &self.streams {
            let c = stream.counts;
            total.slices += c.slices;
            total.frames += c.frames;
            total.steps += c.steps;
            total.received_lines += c.received_lines;
            total.evaluated_lines += c.evaluated_lines;
            total.out_of_order += c.out_of_order;
            total.inconsistent += c.inconsistent;
            total.lost_lines += c.lost_lines;
            total.cut_off_lines += c.cut_off_lines;
            total.incomplete_frames += c.incomplete_frames;
        }
        self.slices.stream = total;
    }

    fn account(&mut self, result: Result<ImageStats, arcnav_perception::SliceError>) {
        match result {
            Ok(stats) => self.totals.accumulate(&stats),
            Err(e) => {
                tracing::warn!(%e, "range slice dropped by perception");
                self.slices.invalid += 1;
            }
        }
    }

    /// Hands `report` on with the heights of the slices since the last
    /// one, and the holes the evidence suspected in them.
    fn send(
        pending: &mut ObstacleReport,
        reports: &mut u64,
        mut report: ObstacleReport,
        out: &mut dyn FnMut(ObstacleReport),
    ) {
        report.heights_cell_m = pending.heights_cell_m;
        report.heights.append(&mut pending.heights);
        let offset = report.regions.len() as u32;
        report.regions.append(&mut pending.regions);
        report.cells.extend(pending.cells.drain(..).map(|mut cell| {
            cell.region += offset;
            cell
        }));
        report.shadows.append(&pending.shadows);
        pending.shadows.clear();
        *reports += 1;
        out(report);
    }

    fn drain(&mut self, out: &mut dyn FnMut(ObstacleReport)) {
        let newest = self.newest_pose();
        while self
            .waiting
            .front()
            .is_some_and(|pending| pending.due(self.extrapolation_us) <= newest)
        {
            if self.fuse_within_us > 0
                && let Some(Pending::Image(_)) = self.waiting.front()
            {
                let Some(partners) = self.partners(newest) else {
                    break; // waits for the images it is fused with
                };
                let mut group = Vec::with_capacity(partners.len() + 1);
                // Taken from the back first, so that the indices hold.
                for &i in partners.iter().rev() {
                    if let Some(Pending::Image(image)) = self.waiting.remove(i) {
                        group.push(image);
                    }
                }
                if let Some(Pending::Image(image)) = self.waiting.pop_front() {
                    group.push(image);
                }
                group.reverse();
                match <[RangeImage; 1]>::try_from(group) {
                    Ok([image]) => self.evaluate(image, out),
                    Err(group) => self.evaluate_fused(group, out),
                }
                continue;
            }
            match self.waiting.pop_front() {
                Some(Pending::Image(image)) => self.evaluate(image, out),
                Some(Pending::Slice(slice)) => self.evaluate_slice(slice, out),
                None => {}
            }
        }
        // Images whose pose never comes (a stopped pose stream) are dropped.
        while self.waiting.len() > self.max_waiting * self.slices_per_image() {
            self.waiting.pop_front();
            self.drops.no_pose += 1;
        }
    }

    /// The images waiting to be fused with the first (indices into
    /// `waiting`, ascending): the first image of each other sensor captured
    /// within `fuse_within_s` after it. `None` while more may come: until
    /// the pose clock passes the window's end, unless every sensor known
    /// (seen, or waiting) is already there.
    fn partners(&self, newest: Utime) -> Option<Vec<usize>> {
        let Some(Pending::Image(first)) = self.waiting.front() else {
            return Some(Vec::new());
        };
        let end = first.utime.saturating_add(self.fuse_within_us);
        let mut found: Vec<(usize, &str)> = Vec::new();
        for (i, pending) in self.waiting.iter().enumerate().skip(1) {
            if let Pending::Image(image) = pending
                && (first.utime..=end).contains(&image.utime)
                && image.sensor != first.sensor
                && found.iter().all(|(_, s)| *s != image.sensor)
            {
                found.push((i, &image.sensor));
            }
        }
        let waiting_sensors = self.waiting.iter().map(|p| match p {
            Pending::Image(image) => image.sensor.as_str(),
            Pending::Slice(slice) => slice.sensor.as_str(),
        });
        let complete = (self.sensors.iter().map(String::as_str))
            .chain(waiting_sensors)
            .all(|s| s == first.sensor || found.iter().any(|(_, f)| *f == s));
        (complete || newest >= end).then(|| found.into_iter().map(|(i, _)| i).collect())
    }

    /// The pose at `t`: interpolated between poses, or carried ahead from
    /// the newest when `t` is after it, by at most `max_gap_us`.
    fn pose_at(
        poses: &PoseHistory,
        newest: Option<Pose>,
        max_gap_us: Utime,
        t: Utime,
    ) -> Option<arcnav_vehicle::Isometry> {
        match newest {
            Some(newest) if newest.utime < t => {
                let ahead = t.checked_sub(newest.utime).filter(|&d| d <= max_gap_us)?;
                Some(newest.extrapolated(ahead).world_from_vehicle)
            }
            _ => poses
                .at_within(t, max_gap_us)
                .ok()
                .map(|p| p.world_from_vehicle),
        }
    }

    /// Whether `sensor` is one of the first [`MAX_SENSORS`] seen (counted
    /// in `drops.too_many_sensors` when not).
    fn admit(&mut self, sensor: &str) -> bool {
        if self.sensors.iter().any(|s| s == sensor) {
            return true;
        }
        if self.sensors.len() < MAX_SENSORS {
            self.sensors.push(sensor.to_owned());
            return true;
        }
        if self.drops.too_many_sensors.is_power_of_two() || self.drops.too_many_sensors == 0 {
            tracing::warn!(
                sensor,
                max = MAX_SENSORS,
                "range data from more sensors than the local map tracks: dropped"
            );
        }
        self.drops.too_many_sensors += 1;
        false
    }

    fn evaluate_slice(&mut self, slice: RangeSlice, out: &mut dyn FnMut(ObstacleReport)) {
        if !self.admit(&slice.sensor) {
            return;
        }
        let newest = self.poses.newest().copied();
        let Some(pose) = Self::pose_at(&self.poses, newest, self.max_gap_us, slice.utime) else {
            tracing::debug!(
                slice = slice.utime,
                "slice dropped: no pose around its last line"
            );
            self.drops.no_pose += 1;
            return;
        };
        // A sensor that streams is newer than its last whole image.
        if self
            .newest_capture
            .iter()
            .any(|(s, newest)| *s == slice.sensor && slice.frame_utime <= *newest)
        {
            self.drops.out_of_order += 1;
            return;
        }
        let index = match self.streams.iter().position(|(s, _)| *s == slice.sensor) {
            Some(i) => i,
            None => {
                let mut stream = FrameStream::new(
                    self.streaming,
                    self.evaluator.support(),
                    &self.perception_config,
                );
                // An evaluator that fuses images sees each frame once, whole.
                stream.set_whole_frames(!self.evaluator.judges_each_image_alone());
                self.streams.push((slice.sensor.clone(), stream));
                self.streams.len() - 1
            }
        };
        // The slice's own heights go with the next report.
        let image = slice.to_image();
        self.heights.sample(&image, &pose, &mut self.pending);
        // Each slice adds to the evidence as it comes: a lidar's slice of
        // columns walks them whole; a scanning sensor's slice of rows walks
        // its own rows only (a gap across two slices is not judged).
        let found = self.evidence.observe(&image, &pose, &mut self.pending);
        self.pending.shadows.append(self.evidence.unverified());
        self.evidence_totals.add(found);
        let stream = &mut self.streams[index].1;
        let (poses, max_gap, newest) = (&self.poses, self.max_gap_us, self.poses.newest().copied());
        let pose_at = |t: Utime| Self::pose_at(poses, newest, max_gap, t);
        let result = stream.on_slice(
            &slice,
            &pose_at,
            self.evaluator.as_mut(),
            &*self.runner,
            &mut |report| Self::send(&mut self.pending, &mut self.reports, report, out),
        );
        self.account(result);
        self.refresh_stream_counts();
    }

    /// The pose `image` was captured at, if it is to be evaluated: from a
    /// sensor admitted, with a pose around its capture time, newer than
    /// any image of its sensor already evaluated (each refusal counted).
    fn admit_image(&mut self, image: &RangeImage) -> Option<Pose> {
        if !self.admit(&image.sensor) {
            return None;
        }
        let pose = match self.poses.at_within(image.utime, self.max_gap_us) {
            Ok(pose) => pose,
            Err(e) => {
                tracing::debug!(%e, image = image.utime, "image dropped: no pose at capture time");
                self.drops.no_pose += 1;
                return None;
            }
        };
        if let Some((_, stream)) = self.streams.iter_mut().find(|(s, _)| *s == image.sensor)
            && stream.frame_utime().is_some_and(|f| image.utime <= f)
        {
            // A whole image no newer than the frame being streamed.
            self.drops.out_of_order += 1;
            return None;
        }
        match self
            .newest_capture
            .iter_mut()
            .find(|(s, _)| *s == image.sensor)
        {
            Some((_, newest)) if image.utime <= *newest => {
                self.drops.out_of_order += 1;
                return None;
            }
            Some((_, newest)) => *newest = image.utime,
            None => self
                .newest_capture
                .push((image.sensor.clone(), image.utime)),
        }
        Some(pose)
    }

    /// Evaluates `image` on its own and hands on its report.
    fn evaluate(&mut self, image: RangeImage, out: &mut dyn FnMut(ObstacleReport)) {
        if let Some(pose) = self.admit_image(&image) {
            self.judge_alone(&image, &pose.world_from_vehicle, out);
        }
    }

    /// Evaluates an admitted image on its own and hands on its report.
    fn judge_alone(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &arcnav_vehicle::Isometry,
        out: &mut dyn FnMut(ObstacleReport),
    ) {
        let mut report = ObstacleReport::default();
        let result =
            (self.evaluator).evaluate_with(image, world_from_vehicle, &mut report, &*self.runner);
        self.deliver(image, world_from_vehicle, report, result, out);
    }

    /// Evaluates images of different sensors captured within
    /// `fuse_within_s` together (those admitted) and hands on a report for
    /// each.
    fn evaluate_fused(&mut self, images: Vec<RangeImage>, out: &mut dyn FnMut(ObstacleReport)) {
        let mut admitted = Vec::with_capacity(images.len());
        for image in images {
            if let Some(pose) = self.admit_image(&image) {
                admitted.push((image, pose.world_from_vehicle));
            }
        }
        match admitted.len() {
            0 => return,
            1 => {
                let (image, pose) = &admitted[0];
                self.judge_alone(image, pose, out);
                return;
            }
            n => {
                self.fused.evaluations += 1;
                self.fused.images += n as u64;
            }
        }
        let mut reports = vec![ObstacleReport::default(); admitted.len()];
        let placed: Vec<_> = admitted.iter().map(|(i, p)| (i, p)).collect();
        let results = (self.evaluator).evaluate_fused(&placed, &mut reports, &*self.runner);
        for (((image, pose), report), result) in admitted.iter().zip(reports).zip(results) {
            self.deliver(image, pose, report, result, out);
        }
    }

    /// Hands on `image`'s report once evaluated, or counts it dropped.
    fn deliver(
        &mut self,
        image: &RangeImage,
        world_from_vehicle: &arcnav_vehicle::Isometry,
        mut report: ObstacleReport,
        result: Result<ImageStats, arcnav_perception::PerceptionError>,
        out: &mut dyn FnMut(ObstacleReport),
    ) {
        match result {
            Ok(stats) => {
                let found = self
                    .evidence
                    .observe(image, world_from_vehicle, &mut report);
                report.shadows.append(self.evidence.unverified());
                self.evidence_totals.add(found);
                report.acquired = image.utime;
                self.heights.sample(image, world_from_vehicle, &mut report);
                self.totals.accumulate(&stats);
                self.reports += 1;
                out(report);
            }
            Err(e) => {
                tracing::warn!(%e, image = image.utime, "image dropped by perception");
                self.drops.invalid += 1;
            }
        }
    }

    /// What fusion did, when `perception.fuse_within_s` asks for it.
    pub fn fusion(&self) -> Option<FusionCounts> {
        (self.fuse_within_us > 0).then_some(self.fused)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use arcnav_perception::SensorModel;
    use arcnav_vehicle::frames::planar_isometry;

    /// A node with the defaults that has had poses at rest every 20 ms for
    /// 3 s (no image yet, so no report).
    fn at_rest_for_3_s() -> PerceptionNode {
        at_rest_with(&PerceptionConfig::default())
    }

    fn at_rest_with(perception: &PerceptionConfig) -> PerceptionNode {
        let mut node = PerceptionNode::new(perception, &PipelineConfig::default()).unwrap();
        for k in 0..=150 {
            let pose = Pose::at_rest(k * 20_000, planar_isometry(0.0, 0.0, 0.0));
            node.on_pose(&pose, &mut |_| panic!("a report before any image"));
        }
        node
    }

    #[test]
    fn an_image_arriving_more_than_a_second_after_its_capture_is_counted_late_and_still_evaluated()
    {
        let mut node = at_rest_for_3_s();
        let mut reports = 0;
        let sensor = SensorModel::erim();
        // Newest pose at 3 s: an image of 0.5 s is late, evaluated all the same.
        node.on_image(sensor.blank_image(500_000), &mut |_| reports += 1);
        assert_eq!((node.late, node.max_lateness_us), (1, 2_500_000));
        assert_eq!(reports, 1);
        // One of 2.5 s is on time.
        node.on_image(sensor.blank_image(2_500_000), &mut |_| reports += 1);
        assert_eq!((node.late, reports), (1, 2));
    }

    #[test]
    fn range_data_from_more_sensors_than_the_map_tracks_is_dropped_and_counted() {
        let mut node = at_rest_for_3_s();
        let mut reports = 0;
        let sensor = SensorModel::erim();
        for i in 0..MAX_SENSORS + 3 {
            let mut image = sensor.blank_image(2_000_000);
            image.sensor = format!("s{i}");
            node.on_image(image, &mut |_| reports += 1);
        }
        assert_eq!(reports, MAX_SENSORS);
        assert_eq!(node.drops.too_many_sensors, 3);
        assert_eq!(node.drops.total(), 3);
        // A sensor already seen still is.
        let mut again = sensor.blank_image(2_500_000);
        again.sensor = "s0".into();
        node.on_image(again, &mut |_| reports += 1);
        assert_eq!(reports, MAX_SENSORS + 1);
    }

    /// With `fuse_within_s`, the images of different sensors captured
    /// within it are judged together, one report each; an image waits for
    /// the others until every sensor known has sent one or the pose clock
    /// passes the window; two images of one sensor are never fused.
    #[test]
    fn images_of_different_sensors_within_fuse_within_s_are_judged_together() {
        let perception = PerceptionConfig {
            evaluator: "height_diff".into(),
            fuse_within_s: 0.05,
            ..PerceptionConfig::default()
        };
        let mut node = at_rest_with(&perception);
        let image = |sensor: &str, utime: Utime| {
            let mut image = SensorModel::erim().blank_image(utime);
            image.sensor = sensor.into();
            image
        };
        let mut reports = 0;
        // Poses every 10 ms up to `t` (the clock stood at 3 s).
        let mut clock = 3_000_000;
        let mut until = |node: &mut PerceptionNode, reports: &mut usize, t: Utime| {
            while clock < t {
                clock += 10_000;
                let pose = Pose::at_rest(clock, planar_isometry(0.0, 0.0, 0.0));
                node.on_pose(&pose, &mut |_| *reports += 1);
            }
        };
        // No sensor known yet: the first is judged alone at once.
        node.on_image(image("a", 2_990_000), &mut |_| reports += 1);
        assert_eq!((reports, node.fused.evaluations), (1, 0));
        // Sensor "a" is known: "b" waits for it...
        until(&mut node, &mut reports, 3_100_000);
        node.on_image(image("b", 3_100_000), &mut |_| reports += 1);
        assert_eq!((reports, node.waiting()), (1, 1));
        // ...and is fused with it, captured 20 ms later.
        until(&mut node, &mut reports, 3_120_000);
        assert_eq!((reports, node.waiting()), (1, 1));
        node.on_image(image("a", 3_120_000), &mut |_| reports += 1);
        assert_eq!((reports, node.waiting()), (3, 0));
        assert_eq!((node.fused.evaluations, node.fused.images), (1, 2));
        // Both known now: "a" waits for "b", whose image is captured 80 ms
        // later, outside the window: "a" alone once the pose clock passes
        // its window, "b" alone once the clock passes its own.
        until(&mut node, &mut reports, 3_200_000);
        node.on_image(image("a", 3_200_000), &mut |_| reports += 1);
        until(&mut node, &mut reports, 3_240_000);
        assert_eq!((reports, node.waiting()), (3, 1));
        until(&mut node, &mut reports, 3_280_000);
        assert_eq!((reports, node.waiting()), (4, 0));
        node.on_image(image("b", 3_280_000), &mut |_| reports += 1);
        assert_eq!((reports, node.waiting()), (4, 1));
        until(&mut node, &mut reports, 3_340_000);
        assert_eq!((reports, node.waiting()), (5, 0));
        assert_eq!((node.fused.evaluations, node.fused.images), (1, 2));
        // A second image of one sensor within the window is not fused with
        // the first: "a" is fused with "b", the second "a" waits for the
        // next "b".
        until(&mut node, &mut reports, 3_420_000);
        node.on_image(image("a", 3_400_000), &mut |_| reports += 1);
        node.on_image(image("a", 3_410_000), &mut |_| reports += 1);
        node.on_image(image("b", 3_405_000), &mut |_| reports += 1);
        assert_eq!((reports, node.waiting()), (7, 1));
        assert_eq!((node.fused.evaluations, node.fused.images), (2, 4));
        assert_eq!(node.drops.total(), 0);
    }
}
