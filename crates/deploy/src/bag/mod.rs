//! rosbag2 bags: a directory holding `metadata.yaml` and one MCAP file, with ROS 2's
//! conventions (profile `ros2`, `ros2msg` schemas, `cdr` messages with their encapsulation
//! header, log time = receive time), the layout ROS 2 tools read (checked with rerun and with
//! Python's `rosbags` and `mcap`). No compression: the aarch64 build stays free of C libraries.
//!
//! The writer runs on a thread of its own ([`BagRecorder`]): the drive loop only hands over
//! bytes, so a slow disk never delays a tick. Chunks of 1 MiB, flushed to the file at least once
//! a second, so a killed recording leaves every complete chunk readable; `metadata.yaml` is
//! written last (temp file and rename) and [`reindex`] rebuilds it from the MCAP file.

pub mod fuzz;

use crate::DeployError;
use std::collections::BTreeMap;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::sync::mpsc;
use std::time::{Duration, Instant};

const SCHEMAS: &str = include_str!("ros2msg.txt");

/// The MCAP file's name inside the bag directory.
pub const MCAP_FILE: &str = "drive_0.mcap";

/// The `ros2msg` schema text of ROS type `ty` (`sensor_msgs/msg/LaserScan`).
pub fn schema_text(ty: &str) -> Option<&'static str> {
    let begin = format!("@@@@ BEGIN {ty} @@@@\n");
    let start = SCHEMAS.find(&begin)? + begin.len();
    let len = SCHEMAS[start..].find(&format!("@@@@ END {ty} @@@@"))?;
    Some(&SCHEMAS[start..start + len])
}

/// `m` as a rosbag2 message payload: the CDR encapsulation header (little-endian) and the
/// message.
pub fn cdr<M: serde::Serialize>(m: &M) -> Vec<u8> {
    let mut out = vec![0, 1, 0, 0];
    // Serialising to memory fails only for types CDR cannot express; ours are all expressible.
    out.extend(cdr_encoding::to_vec::<M, byteorder::LittleEndian>(m).expect("a ROS message serialises to CDR"));
    out
}

/// A message payload decoded (encapsulation header checked: little- or big-endian plain CDR).
pub fn decode<M: serde::de::DeserializeOwned>(data: &[u8]) -> Result<M, String> {
    let (head, body) = data.split_at_checked(4).ok_or("shorter than the CDR header")?;
    match head[..2] {
        [0, 1] => cdr_encoding::from_bytes::<M, byteorder::LittleEndian>(body),
        [0, 0] => cdr_encoding::from_bytes::<M, byteorder::BigEndian>(body),
        _ => return Err(format!("encapsulation {:02x}{:02x} is not plain CDR", head[0], head[1])),
    }
    .map(|(m, _)| m)
    .map_err(|e| e.to_string())
}

/// How a topic was offered: rosbag2 needs it to re-publish (a latched topic is transient local).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Offered {
    /// Sensor data: best effort, volatile.
    Sensor,
    /// Commands and ticks: reliable, volatile.
    Reliable,
    /// Sent once and kept for late joiners (`/tf_static`, `/robot_description`).
    Latched,
}

impl Offered {
    /// rosbag2's `offered_qos_profiles` YAML (version 9 strings).
    fn yaml(self) -> String {
        let (rel, dur) = match self {
            Self::Sensor => ("best_effort", "volatile"),
            Self::Reliable => ("reliable", "volatile"),
            Self::Latched => ("reliable", "transient_local"),
        };
        let inf = "{sec: 9223372036, nsec: 854775807}";
        format!(
            "- history: keep_last\n  depth: 1\n  reliability: {rel}\n  durability: {dur}\n  deadline: {inf}\n  \
             lifespan: {inf}\n  liveliness: automatic\n  liveliness_lease_duration: {inf}\n  \
             avoid_ros_namespace_conventions: false"
        )
    }
}

/// A topic of a bag.
#[derive(Clone, Debug, PartialEq)]
pub struct Topic {
    /// Name (`/scan`).
    pub name: String,
    /// ROS type (`sensor_msgs/msg/LaserScan`).
    pub ty: String,
    /// How it was offered.
    pub offered: Offered,
}

/// What a finished bag holds.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct BagSummary {
    /// Messages per topic, in the order topics were added.
    pub counts: Vec<(Topic, u64)>,
    /// First and last log time, ns since the epoch (simulated time counts from 0).
    pub span_ns: Option<(u64, u64)>,
}

impl BagSummary {
    /// All messages.
    pub fn messages(&self) -> u64 {
        self.counts.iter().map(|(_, n)| n).sum()
    }
}

fn io_err(path: &Path, source: std::io::Error) -> DeployError {
    DeployError::Io {
        path: path.to_path_buf(),
        source,
    }
}

fn mcap_err(path: &Path, e: mcap::McapError) -> DeployError {
    DeployError::Bag(format!("{}: {e}", path.display()))
}

/// The MCAP writer of one bag.
pub struct BagWriter {
    dir: PathBuf,
    path: PathBuf,
    mcap: mcap::Writer<BufWriter<std::fs::File>>,
    channels: Vec<(u16, Topic)>,
    summary: BagSummary,
    sequence: u32,
}

impl BagWriter {
    /// Create bag directory `dir` (it must not exist, or be empty).
    pub fn create(dir: &Path) -> Result<Self, DeployError> {
        if dir.exists() && std::fs::read_dir(dir).map_err(|e| io_err(dir, e))?.next().is_some() {
            return Err(DeployError::Bag(format!(
                "{} exists and is not empty: a bag needs a directory of its own",
                dir.display()
            )));
        }
        std::fs::create_dir_all(dir).map_err(|e| io_err(dir, e))?;
        let path = dir.join(MCAP_FILE);
        let file = std::fs::File::create(&path).map_err(|e| io_err(&path, e))?;
        let mcap = mcap::WriteOptions::new()
            .compression(None)
            .profile("ros2")
            .library(concat!("agvrl-drive ", env!("CARGO_PKG_VERSION")))
            .chunk_size(Some(1 << 20))
            .create(BufWriter::new(file))
            .map_err(|e| mcap_err(&path, e))?;
        Ok(Self {
            dir: dir.to_path_buf(),
            path,
            mcap,
            channels: Vec::new(),
            summary: BagSummary::default(),
            sequence: 0,
        })
    }

    /// Add a topic; its index is what [`BagWriter::write`] takes.
    pub fn add_topic(&mut self, topic: Topic) -> Result<usize, DeployError> {
        let text =
            schema_text(&topic.ty).ok_or_else(|| DeployError::Bag(format!("no ros2msg schema for {}", topic.ty)))?;
        let sid = self
            .mcap
            .add_schema(&topic.ty, "ros2msg", text.as_bytes())
            .map_err(|e| mcap_err(&self.path, e))?;
        let meta = BTreeMap::from([
            ("offered_qos_profiles".to_string(), topic.offered.yaml()),
            ("topic_type_hash".to_string(), String::new()),
        ]);
        let cid = self
            .mcap
            .add_channel(sid, &topic.name, "cdr", &meta)
            .map_err(|e| mcap_err(&self.path, e))?;
        self.channels.push((cid, topic.clone()));
        self.summary.counts.push((topic, 0));
        Ok(self.channels.len() - 1)
    }

    /// Write a message of topic `index` received at `log_ns` (sent at `publish_ns`).
    pub fn write(&mut self, index: usize, log_ns: u64, publish_ns: u64, data: &[u8]) -> Result<(), DeployError> {
        let (cid, _) = self.channels[index];
        self.sequence = self.sequence.wrapping_add(1);
        let header = mcap::records::MessageHeader {
            channel_id: cid,
            sequence: self.sequence,
            log_time: log_ns,
            publish_time: publish_ns,
        };
        self.mcap
            .write_to_known_channel(&header, data)
            .map_err(|e| mcap_err(&self.path, e))?;
        self.summary.counts[index].1 += 1;
        let (a, b) = self.summary.span_ns.get_or_insert((log_ns, log_ns));
        (*a, *b) = ((*a).min(log_ns), (*b).max(log_ns));
        Ok(())
    }

    /// An MCAP metadata record (the policy's hash, its env settings, ...).
    pub fn metadata(&mut self, name: &str, entries: BTreeMap<String, String>) -> Result<(), DeployError> {
        self.mcap
            .write_metadata(&mcap::records::Metadata {
                name: name.to_string(),
                metadata: entries,
            })
            .map_err(|e| mcap_err(&self.path, e))
    }

    /// Close the open chunk and flush it to the file.
    pub fn flush(&mut self) -> Result<(), DeployError> {
        self.mcap.flush().map_err(|e| mcap_err(&self.path, e))
    }

    /// Write the summary and `metadata.yaml`.
    pub fn finish(mut self) -> Result<BagSummary, DeployError> {
        self.mcap.finish().map_err(|e| mcap_err(&self.path, e))?;
        write_metadata_yaml(&self.dir, MCAP_FILE, &self.summary)?;
        Ok(self.summary)
    }
}

/// rosbag2's `metadata.yaml` (version 9) for `s` in MCAP file `file` (a name in `dir`),
/// written to a temp file and renamed.
pub fn write_metadata_yaml(dir: &Path, file: &str, s: &BagSummary) -> Result<(), DeployError> {
    let (start, end) = s.span_ns.unwrap_or((0, 0));
    let mut y = format!(
        "rosbag2_bagfile_information:\n  version: 9\n  storage_identifier: mcap\n  duration:\n    nanoseconds: {}\n  \
         starting_time:\n    nanoseconds_since_epoch: {start}\n  message_count: {}\n  topics_with_message_count:\n",
        end - start,
        s.messages()
    );
    for (t, n) in &s.counts {
        let qos = t.offered.yaml().replace('\n', "\n          ");
        y += &format!(
            "    - topic_metadata:\n        name: {}\n        type: {}\n        serialization_format: cdr\n        \
             offered_qos_profiles:\n          {qos}\n        type_description_hash: \"\"\n      message_count: {n}\n",
            t.name, t.ty
        );
    }
    y += &format!(
        "  compression_format: \"\"\n  compression_mode: \"\"\n  relative_file_paths:\n    - {file}\n  files:\n    \
         - path: {file}\n      starting_time:\n        nanoseconds_since_epoch: {start}\n      duration:\n        \
         nanoseconds: {}\n      message_count: {}\n  custom_data: ~\n  ros_distro: jazzy\n",
        end - start,
        s.messages()
    );
    let path = dir.join("metadata.yaml");
    let tmp = dir.join("metadata.yaml.tmp");
    std::fs::write(&tmp, y).map_err(|e| io_err(&tmp, e))?;
    std::fs::rename(&tmp, &path).map_err(|e| io_err(&path, e))
}

/// One message read back from a bag.
#[derive(Clone, Debug, PartialEq)]
pub struct BagMessage {
    /// Topic name.
    pub topic: String,
    /// ROS type.
    pub ty: String,
    /// Receive time, ns.
    pub log_ns: u64,
    /// Send time, ns.
    pub publish_ns: u64,
    /// CDR payload with its encapsulation header.
    pub data: Vec<u8>,
}

/// The MCAP file of bag `dir`: ours (`drive_0.mcap`), else the one `.mcap` file there (a bag
/// of `ros2 bag record` or rosbags, `<name>_0.mcap`); `dir` may also be the file itself. A split
/// bag (several files) is refused by name.
pub fn mcap_file(dir: &Path) -> Result<PathBuf, DeployError> {
    if dir.is_file() {
        return Ok(dir.to_path_buf());
    }
    let ours = dir.join(MCAP_FILE);
    if ours.exists() {
        return Ok(ours);
    }
    let mut found: Vec<PathBuf> = std::fs::read_dir(dir)
        .map_err(|e| io_err(dir, e))?
        .filter_map(|e| e.ok().map(|e| e.path()))
        .filter(|p| p.extension().is_some_and(|x| x == "mcap"))
        .collect();
    found.sort();
    match found.len() {
        0 => Err(DeployError::Bag(format!(
            "{}: no .mcap file: not a bag with MCAP storage",
            dir.display()
        ))),
        1 => Ok(found.remove(0)),
        _ => Err(DeployError::Bag(format!(
            "{}: {} .mcap files (a split bag); give one file: {}",
            dir.display(),
            found.len(),
            found
                .iter()
                .map(|p| p.display().to_string())
                .collect::<Vec<_>>()
                .join(", ")
        ))),
    }
}

/// Every intact message of bag `dir`'s MCAP file ([`mcap_file`]), in file order. A file cut
/// short (a killed recording) yields every message before the damage and says where it
/// stopped.
pub fn read_messages(dir: &Path) -> Result<(Vec<BagMessage>, Option<String>), DeployError> {
    let path = mcap_file(dir)?;
    let bytes = std::fs::read(&path).map_err(|e| io_err(&path, e))?;
    read_mcap(&bytes, &path)
}

/// Every intact message of MCAP file contents `bytes` (read from `path`, named in errors), as
/// [`read_messages`]: the reader the fuzz target drives.
pub fn read_mcap(bytes: &[u8], path: &Path) -> Result<(Vec<BagMessage>, Option<String>), DeployError> {
    if !bytes.starts_with(mcap::MAGIC) {
        return Err(DeployError::Bag(format!(
            "{}: not an MCAP file (no magic at offset 0)",
            path.display()
        )));
    }
    let mut stream = mcap::MessageStream::new_with_options(bytes, mcap::read::Options::IgnoreEndMagic.into())
        .map_err(|e| mcap_err(path, e))?;
    let mut out = Vec::new();
    // mcap 0.25 panics on some malformed chunks (a slice index in its linear reader, found by
    // the `bag_reader` fuzz target): that is damage like any other, reported, not a crash.
    let damage = loop {
        let next = quiet_catch(|| stream.next());
        match next {
            Ok(None) => break None,
            Ok(Some(Ok(m))) => out.push(BagMessage {
                topic: m.channel.topic.clone(),
                ty: m.channel.schema.as_ref().map_or(String::new(), |s| s.name.clone()),
                log_ns: m.log_time,
                publish_ns: m.publish_time,
                data: m.data.into_owned(),
            }),
            Ok(Some(Err(e))) => break Some(format!("{}: {e} after {} intact messages", path.display(), out.len())),
            Err(p) => {
                let what = p
                    .downcast_ref::<String>()
                    .map(String::as_str)
                    .or_else(|| p.downcast_ref::<&str>().copied())
                    .unwrap_or("a malformed record");
                break Some(format!(
                    "{}: the MCAP reader failed ({what}) after {} intact messages",
                    path.display(),
                    out.len()
                ));
            }
        }
    };
    Ok((out, damage))
}

std::thread_local! {
    static QUIET: std::cell::Cell<bool> = const { std::cell::Cell::new(false) };
}

/// `catch_unwind` whose panic is not printed: the process's panic hook is wrapped once, and
/// stays silent only for this thread and only inside `f` (other threads' panics print as ever).
fn quiet_catch<R>(f: impl FnOnce() -> R) -> std::thread::Result<R> {
    static WRAPPED: std::sync::Once = std::sync::Once::new();
    WRAPPED.call_once(|| {
        let previous = std::panic::take_hook();
        std::panic::set_hook(Box::new(move |info| {
            if !QUIET.with(|q| q.get()) {
                previous(info);
            }
        }));
    });
    QUIET.with(|q| q.set(true));
    let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(f));
    QUIET.with(|q| q.set(false));
    r
}

/// Rebuild `dir/metadata.yaml` from its MCAP file (a recording that was killed before it
/// wrote one); returns the summary and where the file stopped being readable, if it did.
pub fn reindex(dir: &Path) -> Result<(BagSummary, Option<String>), DeployError> {
    let file = mcap_file(dir)?;
    let dir = file.parent().unwrap_or(Path::new("."));
    let name = file
        .file_name()
        .map_or(MCAP_FILE.into(), |n| n.to_string_lossy().into_owned());
    let (msgs, damage) = read_messages(&file)?;
    let mut s = BagSummary::default();
    for m in &msgs {
        let i = match s.counts.iter().position(|(t, _)| t.name == m.topic) {
            Some(i) => i,
            None => {
                let offered = match m.topic.as_str() {
                    "/tf_static" | "/robot_description" => Offered::Latched,
                    "/drive" | "/agvrl/tick" => Offered::Reliable,
                    _ => Offered::Sensor,
                };
                s.counts.push((
                    Topic {
                        name: m.topic.clone(),
                        ty: m.ty.clone(),
                        offered,
                    },
                    0,
                ));
                s.counts.len() - 1
            }
        };
        s.counts[i].1 += 1;
        let (a, b) = s.span_ns.get_or_insert((m.log_ns, m.log_ns));
        (*a, *b) = ((*a).min(m.log_ns), (*b).max(m.log_ns));
    }
    write_metadata_yaml(dir, &name, &s)?;
    Ok((s, damage))
}

enum Rec {
    Msg {
        index: usize,
        log_ns: u64,
        publish_ns: u64,
        data: Vec<u8>,
    },
}

/// A [`BagWriter`] on a thread of its own: `record` only sends the bytes.
pub struct BagRecorder {
    tx: Option<mpsc::Sender<Rec>>,
    thread: Option<std::thread::JoinHandle<Result<BagSummary, DeployError>>>,
}

impl BagRecorder {
    /// Start writing `writer` (its topics added) on its own thread; chunks reach the file at
    /// least once a second.
    pub fn start(mut writer: BagWriter) -> Self {
        let (tx, rx) = mpsc::channel::<Rec>();
        let thread = std::thread::Builder::new()
            .name("agvrl-bag".into())
            .spawn(move || {
                let mut last = Instant::now();
                loop {
                    match rx.recv_timeout(Duration::from_millis(250)) {
                        Ok(Rec::Msg {
                            index,
                            log_ns,
                            publish_ns,
                            data,
                        }) => writer.write(index, log_ns, publish_ns, &data)?,
                        Err(mpsc::RecvTimeoutError::Timeout) => {}
                        Err(mpsc::RecvTimeoutError::Disconnected) => break,
                    }
                    if last.elapsed() >= Duration::from_secs(1) {
                        writer.flush()?;
                        last = Instant::now();
                    }
                }
                writer.finish()
            })
            .expect("spawning the bag writer thread");
        Self {
            tx: Some(tx),
            thread: Some(thread),
        }
    }

    /// Queue a message of topic `index`.
    pub fn record(&self, index: usize, log_ns: u64, publish_ns: u64, data: Vec<u8>) {
        if let Some(tx) = &self.tx {
            // A writer that failed has returned its error; `finish` reports it.
            let _ = tx.send(Rec::Msg {
                index,
                log_ns,
                publish_ns,
                data,
            });
        }
    }

    /// Wait for the writer to drain the queue and finish the bag.
    pub fn finish(mut self) -> Result<BagSummary, DeployError> {
        self.tx.take();
        match self.thread.take().map(|t| t.join()) {
            Some(Ok(r)) => r,
            Some(Err(_)) => Err(DeployError::Bag("the bag writer thread panicked".into())),
            None => Err(DeployError::Bag("the bag was finished twice".into())),
        }
    }
}

impl Drop for BagRecorder {
    fn drop(&mut self) {
        // Dropped without `finish` (an error path): still close the file properly.
        self.tx.take();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// Seconds to integer nanoseconds (negative and non-finite read 0).
pub fn ns(t_s: f64) -> u64 {
    if t_s.is_finite() && t_s > 0.0 {
        (t_s * 1e9).round() as u64
    } else {
        0
    }
}
