//! What can fail when building, opening or reading a dataset.

use crate::labels::LabelError;
use learner_node::log::ReadError;
use std::path::PathBuf;

/// A dataset failure; names the file (log, shard, table) and the value at
/// fault.
#[derive(Debug, thiserror::Error)]
pub enum DatasetError {
    /// A file or directory could not be read, created or written.
    #[error("{}: {source}", path.display())]
    Io {
        /// The file or directory.
        path: PathBuf,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// An imported HDF5 file differs from the authors' layout
    /// (`learner dataset import`).
    #[error("{}: key '{key}': expected {expected}, found {found}", file.display())]
    Import {
        /// The file.
        file: PathBuf,
        /// The key (dataset) at fault; "(file)" for the file itself.
        key: String,
        /// What the layout asks for.
        expected: String,
        /// What the file has.
        found: String,
    },
    /// An input given for the build does not exist.
    #[error("{}: no such file or directory", .0.display())]
    NoInput(PathBuf),
    /// meta.json or stats.json does not parse (or could not be printed).
    #[error("{}: {source}", path.display())]
    Json {
        /// The file.
        path: PathBuf,
        /// Why.
        #[source]
        source: serde_json::Error,
    },
    /// meta.json is of another format version.
    #[error(
        "dataset {}: format version {found}, this build reads version {expected}; rebuild it \
         from its logs with `learner dataset build`",
        dir.display()
    )]
    FormatVersion {
        /// The dataset.
        dir: PathBuf,
        /// The version in meta.json.
        found: u32,
        /// [`super::FORMAT_VERSION`].
        expected: u32,
    },
    /// A shard does not start with this format version's magic.
    #[error(
        "dataset shard {}: starts with {found:?}, not {expected:?}: a shard of another format \
         version (this build reads version {version}); rebuild the dataset from its logs with \
         `learner dataset build`",
        path.display()
    )]
    ShardMagic {
        /// The shard.
        path: PathBuf,
        /// Its first bytes, as text.
        found: String,
        /// [`super::SHARD_MAGIC`], as text.
        expected: String,
        /// [`super::FORMAT_VERSION`].
        version: u32,
    },
    /// The pairing table (wrench.bin) does not match meta.json.
    #[error("{}: holds {bytes} bytes, {samples} samples need {need}", path.display())]
    WrenchTable {
        /// The file.
        path: PathBuf,
        /// Its size.
        bytes: u64,
        /// Samples in meta.json.
        samples: u64,
        /// The size they need.
        need: u64,
    },
    /// The contact table (contacts.bin) does not match meta.json.
    #[error("{}: holds {entries} entries for {samples} samples", path.display())]
    ContactTable {
        /// The file.
        path: PathBuf,
        /// Its entries.
        entries: u64,
        /// Samples in meta.json.
        samples: u64,
    },
    /// A shard ends inside a block.
    #[error(
        "dataset shard {}: block at byte offset {offset} is cut short: {source}",
        path.display()
    )]
    BlockCut {
        /// The shard.
        path: PathBuf,
        /// Where the block starts.
        offset: u64,
        /// Why.
        #[source]
        source: std::io::Error,
    },
    /// A block does not decompress.
    #[error("dataset shard {}: block at byte offset {offset}: {source}", path.display())]
    BlockDecompress {
        /// The shard.
        path: PathBuf,
        /// Where the block starts.
        offset: u64,
        /// zstd's error.
        #[source]
        source: std::io::Error,
    },
    /// A block decompresses to another size than its samples need.
    #[error(
        "dataset shard {}: block at byte offset {offset} holds {got} bytes, expected {expected}",
        path.display()
    )]
    BlockSize {
        /// The shard.
        path: PathBuf,
        /// Where the block starts.
        offset: u64,
        /// Bytes it holds.
        got: usize,
        /// Bytes its samples need.
        expected: usize,
    },
    /// A sample id past the last block.
    #[error("sample {0} is in no block")]
    NoSuchSample(u64),
    /// Block or shard size of zero in the build configuration.
    #[error(
        "block and shard sizes must be > 0 (block_samples {block_samples}, shard_samples \
         {shard_samples})"
    )]
    EmptyBlocks {
        /// Samples per block.
        block_samples: usize,
        /// Samples per shard.
        shard_samples: usize,
    },
    /// The flow mask's motion threshold is negative or not a number.
    #[error("flow_mask_min_px {0} must be a finite number of pixels ≥ 0")]
    FlowMaskThreshold(f64),
    /// A log's images are not of the dataset's size.
    #[error(
        "{}: images of {}×{}, the dataset's are {}×{}",
        log.display(), size.0, size.1, dataset.0, dataset.1
    )]
    ImageSize {
        /// The log.
        log: PathBuf,
        /// Its image size (width, height).
        size: (usize, usize),
        /// The dataset's.
        dataset: (usize, usize),
    },
    /// A log's camera (image size, intrinsics or pose) changes within the
    /// episode.
    #[error("{}: the camera's calibration changes within the episode", .0.display())]
    CameraChanges(PathBuf),
    /// A log's camera is not the one of the dataset's other logs: a model
    /// trained on both would learn two scenes as one.
    #[error(
        "{}: its camera differs from the dataset's (log: {log_camera}; dataset: {dataset}); \
         build one dataset per camera",
        log.display()
    )]
    Camera {
        /// The log.
        log: PathBuf,
        /// Its camera.
        log_camera: Box<shared_mem_schema::CameraCalibration>,
        /// The dataset's (its first episode's).
        dataset: Box<shared_mem_schema::CameraCalibration>,
    },
    /// A log has no `/config` record.
    #[error("{}: no configuration message on /config", .0.display())]
    NoConfig(PathBuf),
    /// A log has no sensor frames.
    #[error("{}: no sensor frames", .0.display())]
    NoSensorFrames(PathBuf),
    /// A collection episode cut short by a stop (its outcome says
    /// interrupted): a resumed collection runs it again, or, past its state
    /// budget, leaves it out, so it is not one of the collection's episodes.
    #[error(
        "{}: cut short by a stop (its outcome says interrupted); a resumed collection \
         (`learner collect --resume`) runs it again or leaves it out",
        .0.display()
    )]
    Interrupted(PathBuf),
    /// The robot a log names does not load.
    #[error("{}: robot {robot}: {source}", log.display())]
    Robot {
        /// The log.
        log: PathBuf,
        /// The robot description it names.
        robot: String,
        /// Why (boxed: the error is large and this path is rare).
        #[source]
        source: Box<robot_model::ModelError>,
    },
    /// A log's sensor frames disagree with its robot's joint count.
    #[error(
        "{}: the sensor frame of step {step} reports {n_joints} joints, robot {robot} has {model}",
        log.display()
    )]
    JointCount {
        /// The log.
        log: PathBuf,
        /// The frame's step.
        step: u64,
        /// Joints the frame reports.
        n_joints: u32,
        /// The robot the log names.
        robot: String,
        /// Joints the robot has.
        model: usize,
    },
    /// Labelling a log panicked (a defect, reported and the log skipped
    /// so that the rest of the build goes on).
    #[error("{}: labelling failed unexpectedly: {message}", log.display())]
    LabelPanic {
        /// The log.
        log: PathBuf,
        /// The panic's message.
        message: String,
    },
    /// meta.json describes something this dataset cannot be (tables out of
    /// range, a foreign sample layout, a path out of the directory).
    #[error("{}: {what}", path.display())]
    BadMeta {
        /// meta.json.
        path: PathBuf,
        /// The field and what is wrong with it.
        what: String,
    },
    /// A block's bytes are not those written.
    #[error(
        "dataset shard {}: block at byte offset {offset} fails its checksum (crc32 0x{computed:08x}, \
         meta.json says 0x{stored:08x}): the shard is damaged",
        path.display()
    )]
    BlockChecksum {
        /// The shard.
        path: PathBuf,
        /// Where the block starts.
        offset: u64,
        /// The checksum in meta.json.
        stored: u32,
        /// The checksum of the bytes read.
        computed: u32,
    },
    /// No flow labeler for a log's camera and task.
    #[error("{}: {source}", log.display())]
    Labels {
        /// The log.
        log: PathBuf,
        /// Why (boxed: the error is large and this path is rare).
        #[source]
        source: Box<LabelError>,
    },
    /// The contact sheet could not be written.
    #[error("writing {}: {source}", path.display())]
    Sheet {
        /// The image file.
        path: PathBuf,
        /// Why.
        #[source]
        source: stack_common::png::PngError,
    },
    /// A log could not be read.
    #[error(transparent)]
    Log(#[from] ReadError),
}

/// Results of the dataset module.
pub type Result<T, E = DatasetError> = std::result::Result<T, E>;
