"""tacmesh's side of DepthAI, run only by the one thread of the tacmesh process that owns the
embedded Python interpreter (see interpreter.rs).

Rust calls these functions and methods and gets plain tuples back, so that it copies frames out
without knowing DepthAI's classes. Everything DepthAI does stays in this file.
"""

import datetime
import os

# Set before depthai is imported: it reads them when it loads. A robot daemon does not phone
# home: telemetry, crash-dump uploads, start-up notifications and model-zoo internet checks are
# off. DepthAI's own SIGSEGV/SIGINT handlers would fight tacmesh's shutdown handling.
QUIET = {
    "DEPTHAI_TELEMETRY": "0",
    "DEPTHAI_DISABLE_CRASHDUMP_COLLECTION": "1",
    "DEPTHAI_DISABLE_STARTUP_NOTIFICATIONS": "1",
    "DEPTHAI_DISABLE_FEEDBACK": "1",
    "DEPTHAI_ZOO_INTERNET_CHECK": "0",
    "DEPTHAI_INSTALL_SIGNAL_HANDLER": "0",
}

dai = None


def load():
    """Imports depthai. Returns its version and the settings the operator's environment
    overrode (kept, and reported by tacmesh)."""
    global dai
    kept = []
    # DepthAI keeps its cache (and, even with telemetry off, an id file) in ~/.cache/depthai;
    # under systemd a service has a cache directory of its own (CacheDirectory=).
    if "DEPTHAI_CACHE_DIR" not in os.environ and os.environ.get("CACHE_DIRECTORY"):
        cache = os.environ["CACHE_DIRECTORY"].split(":")[0]
        os.environ["DEPTHAI_CACHE_DIR"] = os.path.join(cache, "depthai")
    for key, value in QUIET.items():
        if os.environ.get(key, value) != value:
            kept.append(f"{key}={os.environ[key]}")
        else:
            os.environ[key] = value
    import depthai

    dai = depthai
    return depthai.__version__, kept


def _unpack(msg):
    """One ImgFrame → (bytes, width, height, stride, type, matrix or None, sequence, seconds)."""
    transformation = msg.getTransformation()
    matrix = None
    if transformation.isValid():
        matrix = [list(map(float, row)) for row in transformation.getIntrinsicMatrix()]
    return (
        msg.getData().tobytes(),
        msg.getWidth(),
        msg.getHeight(),
        msg.getStride(),
        msg.getType().name,
        matrix,
        msg.getSequenceNum(),
        msg.getTimestamp().total_seconds(),
    )


class Live:
    """A stereo-depth pipeline on an OAK camera."""

    def __init__(self, device, search_timeout_ms, width, height, fps, socket, preset, record):
        os.environ["DEPTHAI_SEARCH_TIMEOUT"] = str(search_timeout_ms)
        # Raises RuntimeError("No available devices") once the search times out.
        self.device = dai.Device(dai.DeviceInfo(device)) if device else dai.Device()
        self.name = self.device.getDeviceId()
        self.pipeline = dai.Pipeline(self.device)
        board_socket = getattr(dai.CameraBoardSocket, socket)
        stereo = self.pipeline.create(dai.node.StereoDepth).build(
            autoCreateCameras=True,
            presetMode=getattr(dai.node.StereoDepth.PresetMode, preset),
            size=(width, height),
            fps=fps,
        )
        stereo.setDepthAlign(board_socket)
        stereo.setOutputSize(width, height)
        stereo.setLeftRightCheck(True)
        # Non-blocking and short: a slow reader loses the oldest frames, the camera never waits.
        self.queue = stereo.depth.createOutputQueue(maxSize=2, blocking=False)
        if record:
            recorder = self.pipeline.create(dai.node.RecordMessage)
            recorder.setRecordFile(record)
            stereo.depth.link(recorder.input)
        calibration = self.device.readCalibration()
        self.intrinsics = [
            list(map(float, row))
            for row in calibration.getCameraIntrinsics(board_socket, width, height)
        ]
        self.pipeline.start()

    def next(self, timeout_s):
        """The next frame, or None if none came within the timeout."""
        msg = self.queue.get(datetime.timedelta(seconds=timeout_s))
        return None if msg is None else _unpack(msg)

    def running(self):
        return self.pipeline.isRunning()

    def close(self):
        # Stop and wait: a pipeline left running while the interpreter's objects are torn down
        # crashes the process at exit.
        self.pipeline.stop()
        self.pipeline.wait()
        self.device.close()


class Replay:
    """A DepthAI `.mcap` recording of depth frames, played host-only (no device)."""

    def __init__(self, path, looping, max_rate):
        self.looping = looping
        self.pipeline = dai.Pipeline(False)
        replay = self.pipeline.create(dai.node.ReplayMessage)
        replay.setReplayFile(path)
        replay.setLoop(looping)
        if max_rate:
            replay.setFps(1000.0)
        # Blocking: a recording is read without losing frames; the replay node waits for us.
        self.queue = replay.out.createOutputQueue(maxSize=2, blocking=True)
        self.pipeline.start()

    def next(self, timeout_s):
        """The next frame; None if none came within the timeout; "end" after the last one."""
        try:
            msg = self.queue.get(datetime.timedelta(seconds=timeout_s))
        except dai.MessageQueue.QueueException:
            # The player closes its queue after the last message; a message it had just sent
            # may go with it, so recordings made by Recorder end with a marker instead.
            return "end"
        if msg is None:
            return None
        if _is_end_marker(msg):
            return None if self.looping else "end"
        return _unpack(msg)

    def running(self):
        return self.pipeline.isRunning()

    def close(self):
        self.pipeline.stop()
        self.pipeline.wait()


# The end of a recording, both ways, loses messages unless marked:
# - the recorder writes a message some time after taking it from its queue, and stopping its
#   pipeline drops what it has not written yet;
# - the player closes its output queue after the last message, and a message it had just sent
#   may go with the queue (measured: the last of 12 frames lost in about 1 replay in 15).
# So Recorder ends a recording with two 1x1 marker frames: once the recorder has taken the
# second off its queue, the first is written. The player stops at the first marker (or skips
# markers when looping). No depth camera makes 1x1 frames; the player renumbers sequence
# numbers when it loops, so the size is the mark.
END_MARKER_SEQUENCE = 0x7FFFFFFF


def _is_end_marker(msg):
    return msg.getWidth() == 1 and msg.getHeight() == 1


class Recorder:
    """Writes depth frames into a DepthAI `.mcap` recording with DepthAI's own recorder,
    host-only, so that a recording can be made without a camera (tests, CI)."""

    def __init__(self, path):
        self.pipeline = dai.Pipeline(False)
        recorder = self.pipeline.create(dai.node.RecordMessage)
        recorder.setRecordFile(path)
        self.input = recorder.input
        self.queue = recorder.input.createInputQueue(maxSize=4, blocking=True)
        self.pipeline.start()

    def send(self, data, width, height, fx, fy, cx, cy, sequence, seconds):
        self.queue.send(self._frame(data, width, height, fx, fy, cx, cy, sequence, seconds))

    def _frame(self, data, width, height, fx, fy, cx, cy, sequence, seconds):
        import numpy

        frame = dai.ImgFrame()
        frame.setType(dai.ImgFrame.Type.RAW16)
        frame.setFrame(numpy.frombuffer(data, dtype=numpy.uint16).reshape(height, width))
        frame.setWidth(width)
        frame.setHeight(height)
        frame.setSequenceNum(sequence)
        frame.setTimestamp(datetime.timedelta(seconds=seconds))
        frame.setTransformation(
            dai.ImgTransformation(width, height, [[fx, 0.0, cx], [0.0, fy, cy], [0.0, 0.0, 1.0]])
        )
        return frame

    def close(self, timeout_s=30.0):
        import time

        for _ in range(2):
            marker = self._frame(b"\0\0", 1, 1, 1.0, 1.0, 0.5, 0.5, END_MARKER_SEQUENCE, 0.0)
            self.queue.send(marker)
        deadline = time.monotonic() + timeout_s
        while self.input.getSize() > 0 and time.monotonic() < deadline:
            time.sleep(0.005)
        taken = self.input.getSize() == 0
        self.pipeline.stop()
        self.pipeline.wait()
        if not taken:
            raise RuntimeError(f"the recorder did not take every frame within {timeout_s} s")
