//! The one thread that owns the embedded Python interpreter.
//!
//! CPython can be initialised once per process and DepthAI's Python objects must not be
//! touched concurrently, so every Python call of this crate happens on this thread: sources
//! send it commands over a channel, it runs the pipelines in `bridge.py`, polls their queues,
//! copies each frame's bytes into a Rust buffer while it holds the GIL, and hands the buffer to
//! the source's channel. The daemon's other threads never take the GIL.

use std::collections::BTreeMap;
use std::ffi::CString;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;
use std::time::Duration;

use crossbeam_channel::{Receiver, Sender, TrySendError};
use pyo3::prelude::*;
use pyo3::types::PyBytes;
use tacmesh_source::Intrinsics;

use crate::frame::{intrinsics_from_matrix, RawDepthImage};
use crate::options::{DepthAiOptions, Mode};
use crate::venv::VirtualEnv;
use crate::DepthAiError;

/// What the interpreter thread hands a source.
#[derive(Debug)]
pub(crate) enum Delivery {
    Frame(RawDepthImage),
    /// A recording played to its end.
    End,
    /// The stream failed and was closed.
    Failed(DepthAiError),
}

/// A stream the interpreter thread opened.
#[derive(Debug)]
pub(crate) struct Opened {
    pub id: u64,
    /// The device id, or the recording's path.
    pub name: String,
    /// From the device's calibration (live cameras only).
    pub intrinsics: Option<Intrinsics>,
}

/// One frame to record: RAW16 millimetres, row-major without padding.
#[derive(Debug, Clone)]
pub(crate) struct RecordFrame {
    pub raw16: Vec<u8>,
    pub intrinsics: Intrinsics,
    pub sequence: i64,
    pub timestamp: Duration,
}

enum Command {
    Open {
        options: Box<DepthAiOptions>,
        frames: Sender<Delivery>,
        reply: Sender<Result<Opened, DepthAiError>>,
    },
    Close {
        id: u64,
        done: Sender<()>,
    },
    Record {
        path: PathBuf,
        frames: Vec<RecordFrame>,
        reply: Sender<Result<usize, DepthAiError>>,
    },
}

/// The running interpreter thread: where to send commands, and what it loaded.
pub(crate) struct Interpreter {
    commands: Sender<Command>,
    venv: Option<PathBuf>,
    pub python: String,
    pub depthai: String,
}

static INTERPRETER: OnceLock<Result<Interpreter, String>> = OnceLock::new();

/// How long one poll of a stream's queue waits, shared out between the open streams, so that
/// commands are never kept waiting longer.
const POLL: Duration = Duration::from_millis(20);
/// Frames a source may have waiting before a live camera's newest frame is dropped.
const FRAMES_IN_FLIGHT: usize = 2;

impl Interpreter {
    /// The process's interpreter thread, started on first use with `venv` (else
    /// `$VIRTUAL_ENV`) on its path. A later call naming another venv is refused: one process
    /// has one interpreter.
    pub fn get(venv: Option<&Path>) -> Result<&'static Interpreter, DepthAiError> {
        let venv = venv
            .map(Path::to_path_buf)
            .or_else(|| std::env::var_os("VIRTUAL_ENV").map(PathBuf::from));
        if INTERPRETER.get().is_none() {
            // A venv that is not one fails here without starting (and so fixing) the
            // interpreter; its Python version is checked once Python runs.
            if let Some(root) = &venv {
                VirtualEnv::read(root)?;
            }
        }
        let started = INTERPRETER.get_or_init(|| start(venv.clone()).map_err(|e| e.to_string()));
        let interpreter = started
            .as_ref()
            .map_err(|e| DepthAiError::InterpreterGone(e.clone()))?;
        if let Some(asked) = venv.filter(|v| Some(v) != interpreter.venv.as_ref()) {
            return Err(DepthAiError::Venv {
                venv: asked,
                reason: format!(
                    "this process's Python was already started with {}; one process has one \
                     interpreter, so every depthai sensor must name the same venv",
                    interpreter
                        .venv
                        .as_ref()
                        .map_or("no venv".into(), |v| v.display().to_string())
                ),
            });
        }
        Ok(interpreter)
    }

    pub fn open(
        &self,
        options: &DepthAiOptions,
    ) -> Result<(Opened, Receiver<Delivery>), DepthAiError> {
        let (frames, receiver) = crossbeam_channel::bounded(FRAMES_IN_FLIGHT);
        let (reply, answer) = crossbeam_channel::bounded(1);
        self.send(Command::Open {
            options: Box::new(options.clone()),
            frames,
            reply,
        })?;
        let opened = answer
            .recv()
            .map_err(|_| DepthAiError::InterpreterGone("it stopped while opening".into()))??;
        Ok((opened, receiver))
    }

    /// Stops and waits for the stream's pipeline; gives up waiting after `patience`.
    pub fn close(&self, id: u64, patience: Duration) {
        let (done, finished) = crossbeam_channel::bounded(1);
        if self.send(Command::Close { id, done }).is_ok()
            && finished.recv_timeout(patience).is_err()
        {
            tracing::warn!("DepthAI stream {id} did not stop within {patience:?}");
        }
    }

    pub fn record(&self, path: &Path, frames: Vec<RecordFrame>) -> Result<usize, DepthAiError> {
        let (reply, answer) = crossbeam_channel::bounded(1);
        self.send(Command::Record {
            path: path.to_path_buf(),
            frames,
            reply,
        })?;
        answer
            .recv()
            .map_err(|_| DepthAiError::InterpreterGone("it stopped while recording".into()))?
    }

    fn send(&self, command: Command) -> Result<(), DepthAiError> {
        self.commands
            .send(command)
            .map_err(|_| DepthAiError::InterpreterGone("its thread has exited".into()))
    }
}

/// Starts the interpreter thread and waits until it has imported depthai (or failed to).
fn start(venv: Option<PathBuf>) -> Result<Interpreter, DepthAiError> {
    let (commands, inbox) = crossbeam_channel::unbounded();
    let (ready, started) = crossbeam_channel::bounded(1);
    let thread_venv = venv.clone();
    std::thread::Builder::new()
        .name("depthai-python".into())
        .spawn(move || match load(thread_venv.as_deref()) {
            Ok((bridge, versions)) => {
                let _ = ready.send(Ok(versions));
                serve(bridge, inbox);
            }
            Err(err) => {
                let _ = ready.send(Err(err));
            }
        })
        .map_err(|e| DepthAiError::InterpreterGone(format!("cannot start its thread: {e}")))?;
    let (python, depthai) = started
        .recv()
        .map_err(|_| DepthAiError::InterpreterGone("its thread exited while starting".into()))??;
    tracing::info!(
        "DepthAI {depthai} in embedded Python {python}{}",
        venv.as_ref()
            .map_or(String::new(), |v| format!(" (venv {})", v.display()))
    );
    Ok(Interpreter {
        commands,
        venv,
        python,
        depthai,
    })
}

/// Initialises Python, puts the venv on its path and imports the bridge and depthai.
fn load(venv: Option<&Path>) -> Result<(Py<PyModule>, (String, String)), DepthAiError> {
    Python::initialize();
    Python::attach(|py| {
        let info = py.version_info();
        let python = format!("{}.{}.{}", info.major, info.minor, info.patch);
        if let Some(root) = venv {
            let venv = VirtualEnv::read(root)?;
            venv.check_python((u32::from(info.major), u32::from(info.minor)))?;
            // addsitedir, not sys.path.append: it also runs the venv's .pth files.
            py.import("site")
                .and_then(|site| site.call_method1("addsitedir", (venv.site_packages.clone(),)))
                .map_err(|e| python_error(py, "adding the venv's site-packages", e))?;
        }
        let source = CString::new(include_str!("bridge.py")).map_err(|e| {
            DepthAiError::InterpreterGone(format!("the bridge source has a NUL byte: {e}"))
        })?;
        let bridge = PyModule::from_code(
            py,
            &source,
            c"tacmesh_depthai_bridge.py",
            c"tacmesh_depthai_bridge",
        )
        .map_err(|e| python_error(py, "loading tacmesh's DepthAI bridge", e))?;
        let (depthai, kept): (String, Vec<String>) = bridge
            .getattr("load")
            .and_then(|load| load.call0())
            .and_then(|versions| versions.extract())
            .map_err(|e| DepthAiError::NotInstalled {
                python: python.clone(),
                message: describe(py, &e),
            })?;
        for setting in kept {
            tracing::warn!("DepthAI: {setting} kept from the environment");
        }
        Ok((bridge.unbind(), (python, depthai)))
    })
}

/// A stream open on the interpreter thread.
struct Stream {
    handle: Py<PyAny>,
    frames: Sender<Delivery>,
    /// A recording: wait for room in the channel instead of dropping frames.
    lossless: bool,
    name: String,
    dropped: u64,
}

/// The thread's loop: commands first, then one poll of every stream.
fn serve(bridge: Py<PyModule>, inbox: Receiver<Command>) {
    let mut streams: BTreeMap<u64, Stream> = BTreeMap::new();
    let mut next_id = 1;
    loop {
        let command = if streams.is_empty() {
            match inbox.recv() {
                Ok(command) => Some(command),
                Err(_) => return,
            }
        } else {
            inbox.try_recv().ok()
        };
        if let Some(command) = command {
            match command {
                Command::Open {
                    options,
                    frames,
                    reply,
                } => {
                    let id = next_id;
                    next_id += 1;
                    let result = Python::attach(|py| open(py, &bridge, &options, id));
                    match result {
                        Ok((opened, handle)) => {
                            let lossless = matches!(options.mode, Mode::Replay(_));
                            let name = opened.name.clone();
                            if reply.send(Ok(opened)).is_ok() {
                                streams.insert(
                                    id,
                                    Stream {
                                        handle,
                                        frames,
                                        lossless,
                                        name,
                                        dropped: 0,
                                    },
                                );
                            } else {
                                Python::attach(|py| close(py, &name, &handle));
                            }
                        }
                        Err(err) => {
                            let _ = reply.send(Err(err));
                        }
                    }
                }
                Command::Close { id, done } => {
                    if let Some(stream) = streams.remove(&id) {
                        Python::attach(|py| close(py, &stream.name, &stream.handle));
                    }
                    let _ = done.send(());
                }
                Command::Record {
                    path,
                    frames,
                    reply,
                } => {
                    let result = Python::attach(|py| record(py, &bridge, &path, &frames));
                    let _ = reply.send(result);
                }
            }
            continue;
        }
        poll(&mut streams);
    }
}

/// One poll of every stream; closes those that ended, failed or lost their reader.
fn poll(streams: &mut BTreeMap<u64, Stream>) {
    let wait_s = POLL.as_secs_f64() / streams.len().max(1) as f64;
    let mut finished = Vec::new();
    let mut polled = false;
    for (&id, stream) in streams.iter_mut() {
        if stream.lossless && stream.frames.is_full() {
            continue;
        }
        polled = true;
        let delivery = Python::attach(|py| next_frame(py, stream, wait_s));
        let Some(delivery) = delivery else { continue };
        let last = !matches!(delivery, Delivery::Frame(_));
        let sent = if stream.lossless || last {
            stream.frames.send(delivery).is_ok()
        } else {
            match stream.frames.try_send(delivery) {
                Ok(()) => true,
                Err(TrySendError::Full(_)) => {
                    stream.dropped += 1;
                    if stream.dropped.is_power_of_two() {
                        tracing::debug!(
                            "DepthAI {}: {} frames dropped while the reader was busy",
                            stream.name,
                            stream.dropped
                        );
                    }
                    true
                }
                Err(TrySendError::Disconnected(_)) => false,
            }
        };
        if last || !sent {
            finished.push(id);
        }
    }
    for id in finished {
        if let Some(stream) = streams.remove(&id) {
            Python::attach(|py| close(py, &stream.name, &stream.handle));
        }
    }
    if !polled {
        // Every stream is a recording whose reader is behind: nothing to do for a moment.
        std::thread::sleep(Duration::from_millis(2));
    }
}

/// Polls one stream: a frame, the end, a failure, or `None` (nothing yet).
fn next_frame(py: Python<'_>, stream: &Stream, wait_s: f64) -> Option<Delivery> {
    let result = stream.handle.bind(py).call_method1("next", (wait_s,));
    match result {
        Ok(value) if value.is_none() => None,
        Ok(value) if value.extract::<String>().is_ok_and(|s| s == "end") => Some(Delivery::End),
        Ok(value) => Some(match unpack(&value) {
            Ok(raw) => Delivery::Frame(raw),
            Err(err) => Delivery::Failed(python_error(py, "reading a frame", err)),
        }),
        Err(err) => Some(Delivery::Failed(python_error(
            py,
            &format!("reading from {}", stream.name),
            err,
        ))),
    }
}

type Unpacked<'py> = (
    Bound<'py, PyBytes>,
    u32,
    u32,
    u32,
    String,
    Option<[[f32; 3]; 3]>,
    i64,
    f64,
);

/// Copies a frame tuple from `bridge._unpack` into Rust.
fn unpack(value: &Bound<'_, PyAny>) -> PyResult<RawDepthImage> {
    let (data, width, height, stride_bytes, type_name, intrinsic_matrix, sequence, seconds): Unpacked<'_> =
        value.extract()?;
    Ok(RawDepthImage {
        width,
        height,
        stride_bytes,
        type_name,
        data: data.as_bytes().to_vec(),
        intrinsic_matrix,
        sequence,
        timestamp: Duration::try_from_secs_f64(seconds).unwrap_or_default(),
    })
}

fn open(
    py: Python<'_>,
    bridge: &Py<PyModule>,
    options: &DepthAiOptions,
    id: u64,
) -> Result<(Opened, Py<PyAny>), DepthAiError> {
    let bridge = bridge.bind(py);
    match &options.mode {
        Mode::Live(live) => {
            let record = live
                .record
                .as_ref()
                .map(|p| p.to_string_lossy().into_owned());
            let handle = bridge
                .getattr("Live")
                .and_then(|class| {
                    class.call1((
                        live.device.clone(),
                        options.search_timeout_ms,
                        live.width,
                        live.height,
                        live.fps,
                        live.align.socket(),
                        live.preset.clone(),
                        record,
                    ))
                })
                .map_err(|e| {
                    let message = describe(py, &e);
                    if message.contains("No available devices")
                        || message.contains("Cannot find")
                        || message.contains("No device")
                    {
                        DepthAiError::NoDevice {
                            device: live
                                .device
                                .as_ref()
                                .map_or(String::new(), |d| format!(" named {d}")),
                            timeout_ms: options.search_timeout_ms,
                            message: e.to_string(),
                        }
                    } else {
                        DepthAiError::Python {
                            action: "starting the stereo-depth pipeline".into(),
                            message,
                        }
                    }
                })?;
            let (name, matrix): (String, [[f32; 3]; 3]) = handle
                .getattr("name")
                .and_then(|n| n.extract())
                .and_then(|name| Ok((name, handle.getattr("intrinsics")?.extract()?)))
                .map_err(|e| python_error(py, "reading the device calibration", e))?;
            let intrinsics = intrinsics_from_matrix(matrix, live.width, live.height);
            let intrinsics = match intrinsics {
                Ok(intrinsics) => intrinsics,
                Err(err) => {
                    close(py, &name, &handle.clone().unbind());
                    return Err(err);
                }
            };
            tracing::info!(
                "DepthAI {name}: stereo depth {}×{} at {} Hz aligned to {}, fx {:.1} fy {:.1} \
                 cx {:.1} cy {:.1} from the device calibration (stream {id})",
                live.width,
                live.height,
                live.fps,
                live.align.socket(),
                intrinsics.fx,
                intrinsics.fy,
                intrinsics.cx,
                intrinsics.cy,
            );
            Ok((
                Opened {
                    id,
                    name,
                    intrinsics: Some(intrinsics),
                },
                handle.unbind(),
            ))
        }
        Mode::Replay(replay) => {
            let handle = bridge
                .getattr("Replay")
                .and_then(|class| {
                    class.call1((
                        replay.path.to_string_lossy().into_owned(),
                        replay.looping,
                        replay.max_rate,
                    ))
                })
                .map_err(|e| DepthAiError::Recording {
                    path: replay.path.clone(),
                    reason: format!("DepthAI cannot play it: {}", describe(py, &e)),
                })?;
            Ok((
                Opened {
                    id,
                    name: replay.path.display().to_string(),
                    intrinsics: None,
                },
                handle.unbind(),
            ))
        }
    }
}

/// Stops the stream's pipeline and waits for it; a failure is logged, not raised (the stream
/// is going away either way).
fn close(py: Python<'_>, name: &str, handle: &Py<PyAny>) {
    if let Err(err) = handle.bind(py).call_method0("close") {
        tracing::warn!(
            "DepthAI {name}: stopping the pipeline failed: {}",
            describe(py, &err)
        );
    }
}

fn record(
    py: Python<'_>,
    bridge: &Py<PyModule>,
    path: &Path,
    frames: &[RecordFrame],
) -> Result<usize, DepthAiError> {
    let failed = |e: PyErr| python_error(py, &format!("recording {}", path.display()), e);
    let recorder = bridge
        .bind(py)
        .getattr("Recorder")
        .and_then(|class| class.call1((path.to_string_lossy().into_owned(),)))
        .map_err(failed)?;
    let mut sent = 0;
    let result = frames.iter().try_for_each(|frame| {
        let k = frame.intrinsics;
        recorder
            .call_method1(
                "send",
                (
                    PyBytes::new(py, &frame.raw16),
                    k.width,
                    k.height,
                    k.fx,
                    k.fy,
                    k.cx,
                    k.cy,
                    frame.sequence,
                    frame.timestamp.as_secs_f64(),
                ),
            )
            .map(|_| sent += 1)
    });
    let closed = recorder.call_method0("close");
    result.and(closed).map_err(failed)?;
    Ok(sent)
}

fn python_error(py: Python<'_>, action: &str, err: PyErr) -> DepthAiError {
    DepthAiError::Python {
        action: action.into(),
        message: describe(py, &err),
    }
}

/// The exception with its Python traceback, one line per frame.
fn describe(py: Python<'_>, err: &PyErr) -> String {
    let traceback = err
        .traceback(py)
        .and_then(|tb| tb.format().ok())
        .unwrap_or_default();
    format!(
        "{err}{}",
        if traceback.is_empty() {
            String::new()
        } else {
            format!("\n{traceback}")
        }
    )
}
