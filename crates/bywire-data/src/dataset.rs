//! A training dataset from logs: on a fixed time grid, the actions (command signals by role)
//! and observations (feedback by role), each observation with its age — the time since a frame
//! last carried it, so a model can mask a value the bus stopped refreshing — cut into episodes
//! at every change of control mode, steering mode or E-stop state and at gaps in the commands,
//! and split into training and validation by episode.
//!
//! With the vehicle's geometry and its four wheel speeds and angles, the rows also carry the
//! pose of the 4WS odometry (`bywire_control::kinematics`: the body twist from the four wheels
//! by least squares, integrated as arcs), from the origin at each episode's start: exact
//! kinematics in normal, crab and tank steering alike.
//!
//! [`Builder`] takes records in time order and hands out rows as the grid passes them; it keeps
//! one value and one timestamp per column, so memory does not grow with the log.

use std::time::Duration;

use bywire_core::{Frame, Timestamp};
use bywire_dbc::codec::Decoded;
use bywire_dbc::decoder::Decoder;

pub use crate::latency::ConfigError;
use crate::latency::{bound, locate, Located, SignalRef};
use bywire_control::kinematics::{four_wheel, Odometry, Pose, Swerve, WheelState};
use bywire_vehicle::profile::LoadedProfile;

/// Whether a column is something the driver did or something the vehicle showed.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Role {
    /// A command signal.
    Action,
    /// A feedback signal (with its age).
    Observation,
    /// Computed from observations (the odometry's pose; its age is its oldest input's).
    Derived,
}

impl Role {
    /// Whether its columns have an age beside them.
    pub fn has_age(self) -> bool {
        self != Role::Action
    }
}

/// The odometry's geometry: wheel positions at (±wheelbase/2, ±track/2).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct PoseConfig {
    /// Front to rear axle, m.
    pub wheelbase_m: f64,
    /// Left to right wheel, m.
    pub track_m: f64,
}

/// The pose columns, in order: position (m), heading (rad), body velocity (m/s) and yaw rate.
pub const POSE_COLUMNS: [(&str, &str); 6] = [
    ("odom_x", "m"),
    ("odom_y", "m"),
    ("odom_yaw", "rad"),
    ("odom_vx", "m/s"),
    ("odom_vy", "m/s"),
    ("odom_yaw_rate", "rad/s"),
];

/// One column of the dataset.
#[derive(Debug, Clone, PartialEq)]
pub struct Column {
    /// Its name in the table (`action_steering`, `obs_velocity`, …).
    pub name: String,
    /// What it is.
    pub role: Role,
    /// Where it comes from.
    pub source: SignalRef,
    /// Its unit (from the DBC).
    pub unit: String,
    /// Whether a change of it starts a new episode (control mode, steering mode, E-stop).
    pub cuts_episodes: bool,
}

/// What to build.
#[derive(Debug, Clone, PartialEq)]
pub struct Config {
    /// The columns.
    pub columns: Vec<Column>,
    /// The grid's step.
    pub step: Duration,
    /// A command gap longer than this ends an episode (the next command starts one).
    pub gap: Duration,
    /// The 4WS odometry's pose columns (needs the `obs_wheel_speed_*` and `obs_wheel_angle_*`
    /// columns).
    pub pose: Option<PoseConfig>,
    /// The command message whose gaps cut episodes.
    pub command: Option<String>,
    /// Share of episodes for validation, 0–1.
    pub validation: f64,
    /// Seed of the split.
    pub seed: u64,
}

impl Config {
    /// The actions and observations a loaded vehicle profile binds, on a grid of `rate` Hz:
    /// its roles as they were found in its DBC when it loaded, not looked up again by name.
    pub fn from_profile(loaded: &LoadedProfile, rate: f64) -> Config {
        let (profile, b, db) = (&loaded.profile, &loaded.bindings, &loaded.database);
        let mut columns = Vec::new();
        let mut add = |name: &str, role: Role, message: usize, signal: Option<usize>, cuts| {
            if let Some(source) = signal.and_then(|signal| bound(db, message, signal)) {
                columns.push(Column {
                    name: name.to_string(),
                    role,
                    source,
                    unit: String::new(),
                    cuts_episodes: cuts,
                });
            }
        };
        if let Some(c) = &b.command {
            for (name, signal) in [
                ("action_steering", c.steering),
                ("action_velocity", c.velocity),
                ("action_brake", c.brake),
                ("action_gear", c.gear),
                ("action_steering_mode", c.steering_mode),
                ("action_control_mode", c.control_mode),
            ] {
                add(name, Role::Action, c.message, Some(signal), false);
            }
        }
        if let Some(s) = &b.state {
            for (name, signal, cuts) in [
                ("obs_steering", Some(s.steering), false),
                ("obs_velocity", Some(s.velocity), false),
                ("obs_gear", s.gear, false),
                ("obs_control_mode", Some(s.control_mode), true),
                ("obs_steering_mode", Some(s.steering_mode), true),
                ("obs_estop_state", s.estop_state, true),
                ("obs_watchdog_level", s.watchdog_level, false),
                ("obs_driver_override", s.driver_override, false),
            ] {
                add(name, Role::Observation, s.message, signal, cuts);
            }
        }
        for (prefix, wheels) in [
            ("obs_wheel_speed", &b.wheel_speeds),
            ("obs_wheel_angle", &b.wheel_angles),
        ] {
            if let Some(w) = wheels {
                for (corner, signal) in ["fl", "fr", "rl", "rr"].iter().zip(w.signals) {
                    let name = format!("{prefix}_{corner}");
                    add(&name, Role::Observation, w.message, Some(signal), false);
                }
            }
        }
        if let Some(imu) = &b.imu {
            for (name, signal) in [
                ("obs_imu_yaw_rate", Some(imu.yaw_rate)),
                ("obs_imu_accel_x", imu.accel_x),
                ("obs_imu_accel_y", imu.accel_y),
            ] {
                add(name, Role::Observation, imu.message, signal, false);
            }
        }
        if let Some(battery) = &b.battery {
            for (name, signal) in [
                ("obs_battery_voltage", Some(battery.voltage)),
                ("obs_battery_current", battery.current),
                ("obs_battery_soc", battery.soc),
            ] {
                add(name, Role::Observation, battery.message, signal, false);
            }
        }
        let period = profile.command.as_ref().map_or(20, |c| c.period_ms.max(1));
        let pose = match (&profile.vehicle, &b.wheel_speeds, &b.wheel_angles) {
            (Some(v), Some(_), Some(_)) => Some(PoseConfig {
                wheelbase_m: v.wheelbase_m,
                track_m: v.track_m,
            }),
            _ => None,
        };
        Config {
            columns,
            step: Duration::from_secs_f64(1.0 / rate),
            gap: Duration::from_millis(period.saturating_mul(5)),
            pose,
            command: b
                .command
                .and_then(|c| db.messages.get(c.message))
                .map(|m| m.name.clone()),
            validation: 0.2,
            seed: 0,
        }
    }
}

/// One grid point.
#[derive(Debug, Clone, PartialEq)]
pub struct Row {
    /// Time since the first record, s.
    pub t_s: f64,
    /// The episode (from 0), `None` outside every episode (before the first command, in a gap).
    pub episode: Option<u32>,
    /// Whether its episode is in the validation share.
    pub validation: bool,
    /// Each column's last value (`NaN` before the first).
    pub values: Vec<f64>,
    /// Each column's age, s: since a frame last carried it (`NaN` before the first).
    pub ages: Vec<f64>,
}

/// One episode as the rows show it.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Episode {
    /// Its number.
    pub index: u32,
    /// Its first and last rows' times, s.
    pub start_s: f64,
    /// Its last row's time, s.
    pub end_s: f64,
    /// Its rows.
    pub rows: u64,
    /// Whether it is in the validation share.
    pub validation: bool,
}

/// What a build saw.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Summary {
    /// Records read.
    pub records: u64,
    /// Rows written.
    pub rows: u64,
    /// Rows outside every episode.
    pub rows_outside: u64,
    /// Grid points not written: silences over a minute (or clock jumps) in the logs.
    pub rows_skipped: u64,
    /// The episodes with at least one row, in order.
    pub episodes: Vec<Episode>,
}

/// A silence in the logs longer than this is skipped by the grid (one minute).
const MAX_SILENCE_NS: u64 = 60_000_000_000;

/// The 4WS odometry as the grid goes.
struct PoseState {
    swerve: Swerve<4>,
    odometry: Odometry,
    /// The wheel speed and angle columns, FL FR RL RR.
    speeds: [usize; 4],
    angles: [usize; 4],
    /// Their units to m/s and rad.
    speed_scale: f64,
    angle_scale: f64,
    /// The stretch (episode, or none) the pose counts from.
    stretch: Option<Option<u32>>,
}

impl PoseState {
    fn new(pose: PoseConfig, columns: &[Column]) -> Result<PoseState, ConfigError> {
        let find = |name: String| -> Result<(usize, &Column), ConfigError> {
            columns
                .iter()
                .enumerate()
                .find(|(_, c)| c.name == name)
                .ok_or_else(|| ConfigError(format!("the odometry needs the column {name}")))
        };
        let mut speeds = [0; 4];
        let mut angles = [0; 4];
        let (mut speed_unit, mut angle_unit) = (String::new(), String::new());
        for ((corner, speed), angle) in ["fl", "fr", "rl", "rr"]
            .iter()
            .zip(speeds.iter_mut())
            .zip(angles.iter_mut())
        {
            let (i, c) = find(format!("obs_wheel_speed_{corner}"))?;
            (*speed, speed_unit) = (i, c.unit.clone());
            let (i, c) = find(format!("obs_wheel_angle_{corner}"))?;
            (*angle, angle_unit) = (i, c.unit.clone());
        }
        let speed_scale = match speed_unit.as_str() {
            "m/s" => 1.0,
            "km/h" | "kph" => 1.0 / 3.6,
            other => {
                return Err(ConfigError(format!(
                    "the odometry needs wheel speeds in m/s or km/h, not '{other}'"
                )))
            }
        };
        let angle_scale = match angle_unit.as_str() {
            "deg" | "°" | "degree" | "degrees" => std::f64::consts::PI / 180.0,
            "rad" => 1.0,
            other => {
                return Err(ConfigError(format!(
                    "the odometry needs wheel angles in deg or rad, not '{other}'"
                )))
            }
        };
        Ok(PoseState {
            swerve: four_wheel(pose.wheelbase_m, pose.track_m),
            odometry: Odometry::new(Pose::default()),
            speeds,
            angles,
            speed_scale,
            angle_scale,
            stretch: None,
        })
    }

    /// The pose columns at a grid point `dt` after the last, from the wheels' values there
    /// (the twist held over the step); the pose counts from the origin at each stretch's start.
    fn step(
        &mut self,
        dt: f64,
        episode: Option<u32>,
        values: &[f64],
        ages: &[f64],
    ) -> ([f64; 6], f64) {
        // A new stretch starts at the origin (this point is its first: nothing to integrate).
        let starts = self.stretch != Some(episode);
        if starts {
            self.stretch = Some(episode);
            self.odometry = Odometry::new(Pose::default());
        }
        let mut wheels = [WheelState::default(); 4];
        let mut oldest = 0.0f64;
        for (wheel, (&s, &a)) in wheels.iter_mut().zip(self.speeds.iter().zip(&self.angles)) {
            let (speed, angle) = (values.get(s).copied(), values.get(a).copied());
            let (Some(speed), Some(angle)) = (speed, angle) else {
                return ([f64::NAN; 6], f64::NAN);
            };
            *wheel = WheelState {
                speed: speed * self.speed_scale,
                angle: angle * self.angle_scale,
            };
            for age in [ages.get(s), ages.get(a)] {
                oldest = oldest.max(age.copied().unwrap_or(f64::NAN));
            }
        }
        let finite = wheels
            .iter()
            .all(|w| w.speed.is_finite() && w.angle.is_finite());
        let twist = self.swerve.forward(&wheels).filter(|_| finite);
        let Some(twist) = twist else {
            // Counted again from the next point with every wheel known.
            self.stretch = None;
            return ([f64::NAN; 6], f64::NAN);
        };
        let pose = if starts {
            self.odometry.pose
        } else {
            self.odometry.update(dt, twist)
        };
        (
            [pose.x, pose.y, pose.yaw, twist.vx, twist.vy, twist.omega],
            oldest,
        )
    }
}

/// The streaming builder.
pub struct Builder<'a> {
    decoder: &'a Decoder,
    config: Config,
    /// The columns as the rows carry them: the signals', then the derived.
    all_columns: Vec<Column>,
    pose: Option<PoseState>,
    located: Vec<Located>,
    command: Option<(u32, bool)>,
    values: Vec<f64>,
    seen: Vec<Option<u64>>,
    decoded: Vec<Option<Decoded>>,
    first: Option<u64>,
    last: Option<u64>,
    next_row: u64,
    step_ns: u64,
    last_command: Option<u64>,
    episode: Option<u32>,
    episodes: u32,
    summary: Summary,
}

impl<'a> Builder<'a> {
    /// A builder of `config`'s columns from `decoder`'s messages; an error names a signal the
    /// DBC lacks. Units come from the DBC.
    pub fn new(decoder: &'a Decoder, mut config: Config) -> Result<Builder<'a>, ConfigError> {
        let db = decoder.database();
        let mut located = Vec::new();
        for column in &mut config.columns {
            let (place, unit) = locate(decoder, &column.source)?;
            column.unit = unit;
            located.push(place);
        }
        let command = match &config.command {
            Some(name) => Some(
                db.message_by_name(name)
                    .map(|m| (m.id, m.extended))
                    .ok_or_else(|| {
                        ConfigError(format!("the DBC has no command message '{name}'"))
                    })?,
            ),
            None => None,
        };
        let step_ns = u64::try_from(config.step.as_nanos())
            .unwrap_or(u64::MAX)
            .max(1_000);
        let pose = config
            .pose
            .map(|p| PoseState::new(p, &config.columns))
            .transpose()?;
        let mut all_columns = config.columns.clone();
        if pose.is_some() {
            all_columns.extend(POSE_COLUMNS.iter().map(|(name, unit)| Column {
                name: (*name).to_string(),
                role: Role::Derived,
                source: SignalRef {
                    message: String::new(),
                    signal: String::new(),
                },
                unit: (*unit).to_string(),
                cuts_episodes: false,
            }));
        }
        let n = config.columns.len();
        let most = db
            .messages
            .iter()
            .map(|m| m.signals.len())
            .max()
            .unwrap_or(0);
        Ok(Builder {
            decoder,
            config,
            all_columns,
            pose,
            located,
            command,
            values: vec![f64::NAN; n],
            seen: vec![None; n],
            decoded: vec![None; most],
            first: None,
            last: None,
            next_row: 0,
            step_ns,
            last_command: None,
            episode: None,
            episodes: 0,
            summary: Summary::default(),
        })
    }

    /// Number this builder's episodes from `first` (several runs in one table).
    pub fn offset_episodes(&mut self, first: u32) {
        self.episodes = first;
    }

    /// The columns as the rows carry them (with their units): the signals', then the derived.
    pub fn columns(&self) -> &[Column] {
        &self.all_columns
    }

    /// The next record (in time order); `row` is given each grid point it passes.
    pub fn push(&mut self, at: Timestamp, frame: &Frame, row: &mut dyn FnMut(Row)) {
        let Some(id) = frame.id() else { return };
        let now = at.as_nanos();
        let first = *self.first.get_or_insert(now);
        self.last = Some(now);
        self.summary.records += 1;
        // A silence longer than MAX_SILENCE (or a clock that jumps) is skipped, not filled
        // a row at a time.
        let next = first.saturating_add(self.next_row.saturating_mul(self.step_ns));
        if now.saturating_sub(next) > MAX_SILENCE_NS {
            let target = (now - first) / self.step_ns;
            self.summary.rows_skipped += target.saturating_sub(self.next_row);
            self.next_row = self.next_row.max(target);
            self.episode = None;
        }
        // Grid points before this record see the state before it.
        while first.saturating_add(self.next_row.saturating_mul(self.step_ns)) < now {
            self.emit(first, row);
        }
        let (raw, extended) = (id.as_raw(), id.is_extended());
        if self.command == Some((raw, extended)) {
            let gap = u64::try_from(self.config.gap.as_nanos()).unwrap_or(u64::MAX);
            if self
                .last_command
                .is_none_or(|last| now.saturating_sub(last) > gap)
            {
                self.start_episode();
            }
            self.last_command = Some(now);
        }
        if !self
            .located
            .iter()
            .any(|l| l.raw == raw && l.extended == extended)
        {
            return;
        }
        let Some((_, _, codec)) = self.decoder.message_with_id(raw, extended) else {
            return;
        };
        self.decoded.iter_mut().for_each(|d| *d = None);
        if codec.decode(frame.data(), &mut self.decoded).is_err() {
            return;
        }
        let mut cut = false;
        for (i, l) in self.located.iter().enumerate() {
            if l.raw != raw || l.extended != extended {
                continue;
            }
            let Some(value) = self.decoded.get(l.index).copied().flatten() else {
                continue;
            };
            let value = value.physical.as_f64();
            if let (Some(old), Some(column)) = (self.values.get_mut(i), self.config.columns.get(i))
            {
                cut |= column.cuts_episodes && !old.is_nan() && *old != value;
                *old = value;
            }
            if let Some(seen) = self.seen.get_mut(i) {
                *seen = Some(now);
            }
        }
        if cut && self.episode.is_some() {
            self.start_episode();
        }
    }

    fn start_episode(&mut self) {
        self.episode = Some(self.episodes);
        self.episodes = self.episodes.saturating_add(1);
    }

    /// Whether episode `e` is for validation: a hash of it and the seed against the share.
    fn validation(&self, episode: u32) -> bool {
        let mut x = (u64::from(episode) ^ self.config.seed.rotate_left(17))
            .wrapping_add(0x9E37_79B9_7F4A_7C15);
        x = (x ^ (x >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        x = (x ^ (x >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        x ^= x >> 31;
        let share = (x >> 11) as f64 / (1u64 << 53) as f64;
        share < self.config.validation
    }

    fn emit(&mut self, first: u64, row: &mut dyn FnMut(Row)) {
        let t = first.saturating_add(self.next_row.saturating_mul(self.step_ns));
        self.next_row += 1;
        let gap = u64::try_from(self.config.gap.as_nanos()).unwrap_or(u64::MAX);
        // In a command gap the episode has ended.
        if self.command.is_some() && self.last_command.is_none_or(|last| t - last.min(t) > gap) {
            self.episode = None;
        }
        let episode = self.episode;
        let validation = episode.is_some_and(|e| self.validation(e));
        let mut ages: Vec<f64> = self
            .seen
            .iter()
            .map(|s| s.map_or(f64::NAN, |s| t.saturating_sub(s) as f64 / 1e9))
            .collect();
        let mut values = self.values.clone();
        if let Some(pose) = &mut self.pose {
            let dt = self.step_ns as f64 / 1e9;
            let (derived, age) = pose.step(dt, episode, &values, &ages);
            values.extend(derived);
            ages.extend([age; 6]);
        }
        let t_s = (t - first) as f64 / 1e9;
        match (episode, self.summary.episodes.last_mut()) {
            (Some(e), Some(last)) if last.index == e => {
                last.end_s = t_s;
                last.rows += 1;
            }
            (Some(e), _) => self.summary.episodes.push(Episode {
                index: e,
                start_s: t_s,
                end_s: t_s,
                rows: 1,
                validation,
            }),
            (None, _) => self.summary.rows_outside += 1,
        }
        self.summary.rows += 1;
        row(Row {
            t_s,
            episode,
            validation,
            values,
            ages,
        });
    }

    /// The grid points up to the last record, and the summary.
    pub fn finish(mut self, row: &mut dyn FnMut(Row)) -> Summary {
        if let (Some(first), Some(last)) = (self.first, self.last) {
            while first.saturating_add(self.next_row.saturating_mul(self.step_ns)) <= last {
                self.emit(first, row);
            }
        }
        self.summary
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::indexing_slicing)]

    use super::*;
    use bywire_core::frame::{ClassicFrame, StandardId};
    use bywire_core::Id;

    const DBC: &str = "BO_ 256 Cmd: 8 ADS
 SG_ Steer : 0|16@1- (0.1,0) [-90|90] \"deg\" ECU
BO_ 257 State: 8 ECU
 SG_ Speed : 0|16@1- (0.01,0) [-50|50] \"m/s\" ADS
 SG_ Mode : 16|8@1+ (1,0) [0|3] \"\" ADS
";

    fn frame(id: u16, a: i16, b: u8) -> Frame {
        let a = a.to_le_bytes();
        let data = [a[0], a[1], b, 0, 0, 0, 0, 0];
        Frame::Classic(
            ClassicFrame::new(Id::Standard(StandardId::new(id).unwrap()), &data).unwrap(),
        )
    }

    fn column(name: &str, role: Role, source: &str, cuts: bool) -> Column {
        Column {
            name: name.into(),
            role,
            source: SignalRef::parse(source).unwrap(),
            unit: String::new(),
            cuts_episodes: cuts,
        }
    }

    fn ms(t: u64) -> Timestamp {
        Timestamp::from_nanos(1_000_000_000 + t * 1_000_000)
    }

    /// A hand-made log: commands every 20 ms from 0 to 400 ms, then a 200 ms gap, then again
    /// to 800 ms (the steering angle in 0.1° is the time in ms); the state every 50 ms from
    /// 5 ms until 305 ms, then silent (a stale value), its mode 0 → 1 at 155 ms.
    fn build(config: Config) -> (Vec<Row>, Summary, Vec<Column>) {
        let (db, _) = bywire_dbc::parse(DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let mut builder = Builder::new(&decoder, config).unwrap();
        let columns = builder.columns().to_vec();
        let mut records: Vec<(u64, Frame)> = Vec::new();
        for t in (0..=800).step_by(20) {
            if !(401..600).contains(&t) {
                records.push((t, frame(0x100, i16::try_from(t).unwrap(), 0)));
            }
        }
        for t in (0..=300).step_by(50) {
            records.push((t + 5, frame(0x101, 150, u8::from(t >= 150))));
        }
        records.sort_by_key(|(t, _)| *t);
        let mut rows = Vec::new();
        for (t, f) in &records {
            builder.push(ms(*t), f, &mut |r| rows.push(r));
        }
        let summary = builder.finish(&mut |r| rows.push(r));
        (rows, summary, columns)
    }

    fn config() -> Config {
        Config {
            columns: vec![
                column("action_steer", Role::Action, "Cmd.Steer", false),
                column("obs_speed", Role::Observation, "State.Speed", false),
                column("obs_mode", Role::Observation, "State.Mode", true),
            ],
            step: Duration::from_millis(100),
            gap: Duration::from_millis(50),
            command: Some("Cmd".into()),
            validation: 0.5,
            seed: 3,
            pose: None,
        }
    }

    const WHEELS_DBC: &str = "BU_: VCU\nBO_ 512 Speeds: 8 VCU
 SG_ FL : 0|16@1- (0.001,0) [-30|30] \"m/s\" ADS
 SG_ FR : 16|16@1- (0.001,0) [-30|30] \"m/s\" ADS
 SG_ RL : 32|16@1- (0.001,0) [-30|30] \"m/s\" ADS
 SG_ RR : 48|16@1- (0.001,0) [-30|30] \"m/s\" ADS
BO_ 513 Angles: 8 VCU
 SG_ FL : 0|16@1- (0.01,0) [-180|180] \"deg\" ADS
 SG_ FR : 16|16@1- (0.01,0) [-180|180] \"deg\" ADS
 SG_ RL : 32|16@1- (0.01,0) [-180|180] \"deg\" ADS
 SG_ RR : 48|16@1- (0.01,0) [-180|180] \"deg\" ADS
";

    /// The pose at the end of 2 s of the wheels `states` (sent every 10 ms), on a 50 Hz grid.
    fn pose_after(states: [bywire_control::kinematics::WheelState; 4]) -> Vec<f64> {
        let (db, _) = bywire_dbc::parse(WHEELS_DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let mut columns = Vec::new();
        for (kind, message) in [("speed", "Speeds"), ("angle", "Angles")] {
            for corner in ["fl", "fr", "rl", "rr"] {
                let source = format!("{message}.{}", corner.to_uppercase());
                let name = format!("obs_wheel_{kind}_{corner}");
                columns.push(column(&name, Role::Observation, &source, false));
            }
        }
        let config = Config {
            columns,
            step: Duration::from_millis(20),
            gap: Duration::from_secs(1),
            command: None,
            validation: 0.0,
            seed: 0,
            pose: Some(PoseConfig {
                wheelbase_m: 3.2,
                track_m: 1.8,
            }),
        };
        let mut builder = Builder::new(&decoder, config).unwrap();
        assert_eq!(builder.columns().last().unwrap().name, "odom_yaw_rate");
        #[allow(clippy::cast_possible_truncation)]
        let raw = |v: f64, scale: f64| ((v / scale).round() as i16).to_le_bytes();
        let pack = |f: &dyn Fn(&bywire_control::kinematics::WheelState) -> [u8; 2]| {
            let mut data = [0u8; 8];
            for (k, s) in states.iter().enumerate() {
                data[2 * k..2 * k + 2].copy_from_slice(&f(s));
            }
            data
        };
        let speeds = pack(&|s| raw(s.speed, 0.001));
        let angles = pack(&|s| raw(s.angle.to_degrees(), 0.01));
        let mut last = None;
        for t in (0..=2000).step_by(10) {
            for (id, data) in [(0x200, speeds), (0x201, angles)] {
                let frame = Frame::Classic(
                    ClassicFrame::new(Id::Standard(StandardId::new(id).unwrap()), &data).unwrap(),
                );
                builder.push(ms(t), &frame, &mut |r| last = Some(r));
            }
        }
        builder.finish(&mut |r| last = Some(r));
        let row = last.unwrap();
        row.values[8..].to_vec()
    }

    #[test]
    fn the_odometry_pose_follows_crab_and_tank_steering() {
        use bywire_control::kinematics::{four_wheel, Twist, WheelState};
        let swerve = four_wheel(3.2, 1.8);
        // Crab: 1 m/s at 30° to the left, for 2 s (the pose counts from the first grid point,
        // at 0 s, with every wheel seen).
        let crab = swerve.inverse(
            Twist {
                vx: 30f64.to_radians().cos(),
                vy: 30f64.to_radians().sin(),
                omega: 0.0,
            },
            &[WheelState::default(); 4],
        );
        let pose = pose_after(crab);
        let travelled = 2.0;
        assert!(
            (pose[0] - travelled * 30f64.to_radians().cos()).abs() < 0.01,
            "{pose:?}"
        );
        assert!(
            (pose[1] - travelled * 30f64.to_radians().sin()).abs() < 0.01,
            "{pose:?}"
        );
        assert!(pose[2].abs() < 1e-3, "{pose:?}");
        assert!((pose[4] - 0.5).abs() < 0.002, "{pose:?}");
        // Tank: turning on the spot at 0.3 rad/s.
        let tank = swerve.inverse(
            Twist {
                vx: 0.0,
                vy: 0.0,
                omega: 0.3,
            },
            &[WheelState::default(); 4],
        );
        let pose = pose_after(tank);
        assert!(pose[0].abs() < 0.01 && pose[1].abs() < 0.01, "{pose:?}");
        assert!((pose[2] - 0.3 * travelled).abs() < 0.005, "{pose:?}");
        assert!((pose[5] - 0.3).abs() < 0.001, "{pose:?}");
    }

    #[test]
    fn the_grid_the_ages_and_the_episodes_of_a_hand_made_log() {
        let (rows, summary, columns) = build(config());
        assert_eq!(columns[0].unit, "deg");
        assert_eq!(columns[1].unit, "m/s");
        // The grid: every 100 ms from the first record to the last, values as of just before.
        let times: Vec<f64> = rows.iter().map(|r| r.t_s).collect();
        assert_eq!(times.len(), 9);
        for (k, t) in times.iter().enumerate() {
            assert!((t - k as f64 * 0.1).abs() < 1e-9, "{times:?}");
        }
        // A grid point sees the records at or before it: at 0 the first command only (the
        // state not yet: NaN, no age); at 100 ms the command of 100 ms (10.0°, age 0) and the
        // state of 55 ms (45 ms old).
        assert_eq!(rows[0].values[0], 0.0);
        assert!(rows[0].values[1].is_nan() && rows[0].ages[1].is_nan());
        assert_eq!(rows[1].values[0], 10.0);
        assert_eq!(rows[1].ages[0], 0.0);
        assert!((rows[1].values[1] - 1.5).abs() < 1e-12);
        assert!((rows[1].ages[1] - 0.045).abs() < 1e-9, "{:?}", rows[1].ages);
        // The state stopped at 305 ms: at 800 ms its value is held, 0.495 s old.
        assert!((rows[8].values[1] - 1.5).abs() < 1e-12);
        assert!((rows[8].ages[1] - 0.495).abs() < 1e-9, "{:?}", rows[8].ages);
        // Episodes: the first from the first command, a new one at the mode change (155 ms),
        // none in the command gap (500 ms: 100 ms since the last command, over 50), a third
        // from the command at 600 ms.
        let episodes: Vec<Option<u32>> = rows.iter().map(|r| r.episode).collect();
        assert_eq!(
            episodes,
            [
                Some(0),
                Some(0),
                Some(1),
                Some(1),
                Some(1),
                None,
                Some(2),
                Some(2),
                Some(2)
            ]
        );
        assert_eq!(summary.episodes.len(), 3);
        assert_eq!(summary.rows, 9);
        assert_eq!(summary.rows_outside, 1);
        assert_eq!((summary.episodes[0].rows, summary.episodes[1].rows), (2, 3));
        assert!((summary.episodes[1].start_s - 0.2).abs() < 1e-9);
        // The split is per episode: every row of an episode has its episode's split.
        for r in &rows {
            if let Some(e) = r.episode {
                assert_eq!(
                    r.validation,
                    summary
                        .episodes
                        .iter()
                        .find(|x| x.index == e)
                        .unwrap()
                        .validation
                );
            }
        }
    }

    #[test]
    fn a_long_silence_is_skipped_not_filled() {
        let (db, _) = bywire_dbc::parse(DBC.as_bytes(), bywire_dbc::Mode::Lenient).unwrap();
        let decoder = Decoder::new(db);
        let mut builder = Builder::new(&decoder, config()).unwrap();
        let mut rows = Vec::new();
        // A record, then one a year later: the row at the second, not 315 million.
        builder.push(ms(0), &frame(0x100, 1, 0), &mut |r| rows.push(r));
        let year = 365 * 24 * 3600 * 1000;
        builder.push(ms(year), &frame(0x100, 2, 0), &mut |r| rows.push(r));
        let summary = builder.finish(&mut |r| rows.push(r));
        assert_eq!(rows.len(), 1);
        assert_eq!(summary.rows_skipped, year / 100);
        // Backwards time ends in rows too, never a panic.
        let mut builder = Builder::new(&decoder, config()).unwrap();
        for t in [500, 100, 300, 0, 900] {
            builder.push(ms(t), &frame(0x100, 1, 0), &mut |r| rows.push(r));
        }
        builder.finish(&mut |r| rows.push(r));
    }

    #[test]
    fn the_split_follows_the_share_and_the_seed() {
        let mut all = config();
        all.validation = 1.0;
        let (rows, _, _) = build(all);
        assert!(rows
            .iter()
            .filter(|r| r.episode.is_some())
            .all(|r| r.validation));
        let mut none = config();
        none.validation = 0.0;
        let (rows, _, _) = build(none);
        assert!(rows.iter().all(|r| !r.validation));
    }
}
