"""actengine.convert(calib=paths): the calibration sources act_convert --calib takes (a folder of
images, a video, a LeRobot dataset, an act_drive recording), read by the same code: the same blob and
report as act_convert on each; clear errors on a bad path; progress through logging."""

import json
import logging
import os
import shutil
import struct
import subprocess

import numpy as np
import pytest

import actengine
from conftest import require

# Small and quick, on both sides: 3 calibration frames and 1 held out of the fixture's 4 samples.
OPTIONS = dict(calib_samples=3, holdout=1, threads=2)
CLI_OPTIONS = ["--calib-samples", 3, "--holdout", 1, "--threads", 2]


def require_media():
    """actengine._media (the readers, over OpenCV), which a build with OpenCV has: skipped without it
    locally, a failure under CI=true (CI builds with OpenCV)."""
    try:
        import actengine._media  # noqa: F401
    except ImportError as error:
        message = f"this actengine has no calibration readers (built without OpenCV): {error}"
        if os.environ.get("CI") == "true":
            pytest.fail(message)
        pytest.skip(message)


def write_avi(path, frames, fps=10):
    """An uncompressed AVI (24-bit DIB frames, bottom-up BGR) of RGB uint8 HxWx3 frames: a real video
    FFmpeg decodes losslessly, written without an encoder (the machine has no cv2 or ffmpeg command)."""
    height, width, _ = frames[0].shape
    row = (width * 3 + 3) & ~3
    size = row * height

    def chunk(fourcc, data):
        return fourcc + struct.pack("<I", len(data)) + data + (b"\0" if len(data) % 2 else b"")

    def riff_list(kind, data):
        return chunk(b"LIST", kind + data)

    avih = struct.pack("<14I", 1000000 // fps, size * fps, 0, 0x10, len(frames), 0, 1, size, width, height, 0, 0, 0, 0)
    strh = b"vids" + b"DIB " + struct.pack("<IHHIIIIIIIIhhhh", 0, 0, 0, 0, 1, fps, 0, len(frames), size, 0xFFFFFFFF, 0,
                                           0, 0, width, height)
    strf = struct.pack("<IiiHHIIiiII", 40, width, height, 1, 24, 0, size, 0, 0, 0, 0)
    header = riff_list(b"hdrl", chunk(b"avih", avih) + riff_list(b"strl", chunk(b"strh", strh) + chunk(b"strf", strf)))
    movi, index, offset = b"", b"", 4
    for frame in frames:
        pixels = np.zeros((height, row), np.uint8)
        pixels[:, : width * 3] = frame[::-1, :, ::-1].reshape(height, width * 3)
        data = chunk(b"00db", pixels.tobytes())
        index += b"00db" + struct.pack("<III", 0x10, offset, size)
        offset += len(data)
        movi += data
    body = b"AVI " + header + riff_list(b"movi", movi) + chunk(b"idx1", index)
    path.write_bytes(b"RIFF" + struct.pack("<I", len(body)) + body)
    return path


def image_folder(act_tiny, folder):
    """The fixture's sample frames (PNG), in a subfolder: the readers search folders recursively."""
    (folder / "session").mkdir(parents=True)
    for png in sorted(act_tiny.dir.glob("sample*.png")):
        shutil.copy(png, folder / "session" / png.name)
    return folder


def recording(act_tiny, folder):
    """An act_drive --record folder: log.jsonl naming each frame with the robot state logged with it."""
    image_folder(act_tiny, folder)
    states = act_tiny.ref["input.observation.state"]
    lines = [json.dumps({"t": i, "frame": f"session/{png.name}", "state": states[i].tolist()})
             for i, png in enumerate(sorted((folder / "session").glob("*.png")))]
    (folder / "log.jsonl").write_text("\n".join(lines) + "\n")
    return folder


def lerobot_dataset(act_tiny, folder):
    """A LeRobot dataset folder: meta/info.json and one video per episode per camera key."""
    (folder / "meta").mkdir(parents=True)
    (folder / "meta" / "info.json").write_text("{}")
    videos = folder / "videos" / "chunk-000" / "observation.images.front"
    videos.mkdir(parents=True)
    frames = act_tiny.ref["input.observation.images.front.u8_nhwc"]
    write_avi(videos / "episode_000000.avi", list(frames[:2]))
    write_avi(videos / "episode_000001.avi", list(frames[2:]))
    return folder


def video(act_tiny, folder):
    folder.mkdir()
    return write_avi(folder / "clip.avi", list(act_tiny.ref["input.observation.images.front.u8_nhwc"]))


def act_convert(*args):
    """The act_convert of this build tree (CTest passes its path): (exit code, stderr)."""
    binary = os.environ.get("ACT_CONVERT_BIN", "")
    require(binary)
    run = subprocess.run([binary, *map(str, args)], capture_output=True, text=True, check=False)
    return run.returncode, run.stderr


@pytest.mark.parametrize("kind, make, as_given", [
    ("folder", image_folder, lambda p: p),                  # an os.PathLike
    ("video", video, str),                                  # a str
    ("recording", recording, lambda p: [os.fsencode(p)]),  # a list, of bytes
    ("dataset", lerobot_dataset, lambda p: [str(p)]),
])
def test_each_source_gives_act_converts_blob_and_report(act_tiny, tmp_path, kind, make, as_given):
    require_media()
    source = make(act_tiny, tmp_path / kind)
    result = actengine.convert(act_tiny.dir, tmp_path / "py.actb", calib=as_given(source), **OPTIONS)
    report = result["report"]
    assert (report["calibration_frames"], report["holdout_frames"]) == (3, 1)
    assert report["notes"][0] == "4 frames given, 3 used for calibration, 1 held out"
    # A recording logs its states; the other sources have none, sampled from the statistics instead.
    assert any("states were sampled" in note for note in report["notes"]) == (kind != "recording")

    code, stderr = act_convert(act_tiny.dir, "-o", tmp_path / "cli.actb", "--precision", "int8", "--calib", source,
                               *CLI_OPTIONS, "--report", tmp_path / "cli.json", "-q")
    assert code == 0, stderr
    cli_report = json.loads((tmp_path / "cli.json").read_text())
    assert {k: v for k, v in cli_report.items() if k != "seconds"} == {k: v for k, v in report.items() if k != "seconds"}
    assert (tmp_path / "cli.actb").read_bytes() == (tmp_path / "py.actb").read_bytes()


def test_progress_goes_to_the_actengine_logger(act_tiny, tmp_path, caplog):
    require_media()
    # Square frames for a 96x128 model: stretched, which the readers warn about.
    square = [np.ascontiguousarray(f[:, :96]) for f in act_tiny.ref["input.observation.images.front.u8_nhwc"]]
    lines = []
    with caplog.at_level(logging.DEBUG, logger="actengine"):
        actengine.convert(act_tiny.dir, tmp_path / "py.actb", calib=write_avi(tmp_path / "square.avi", square),
                          progress=lines.append, **OPTIONS)
    records = [r for r in caplog.records if r.name == "actengine"]
    info = [r.getMessage() for r in records if r.levelno == logging.INFO]
    assert info[0] == "reading calibration frames from 1 source(s) ..."
    calibrating = [m for m in info if m.startswith("calibrating (mse): ")]
    assert calibrating[0].endswith(" 0/3 frames") and calibrating[-1].endswith(" 3/3 frames")
    warnings = [r.getMessage() for r in records if r.levelno == logging.WARNING]
    assert len(warnings) == 1 and warnings[0].startswith("warning: calibration frames of 96x96 are stretched")
    # The callback still gets every line; the logger has them all too (the rest at DEBUG).
    assert lines and set(lines) <= {r.getMessage() for r in records}


def test_bad_paths_raise_clear_errors(act_tiny, tmp_path):
    require_media()
    out = tmp_path / "out.actb"
    with pytest.raises(FileNotFoundError) as missing:
        actengine.convert(act_tiny.dir, out, calib=tmp_path / "no-such-folder")
    assert missing.value.filename == str(tmp_path / "no-such-folder")
    assert "calibration source not found" in str(missing.value)

    with pytest.raises(ValueError, match="is not a folder, a video .*, an image or an observation .safetensors file"):
        actengine.convert(act_tiny.dir, out, calib=act_tiny.dir / "config.json")
    (tmp_path / "empty").mkdir()
    with pytest.raises(actengine.Error, match="has no images"):
        actengine.convert(act_tiny.dir, out, calib=tmp_path / "empty")
    (tmp_path / "broken.mp4").write_bytes(b"not a video")
    with pytest.raises(actengine.Error, match=r"cannot open video .*broken\.mp4"):
        actengine.convert(act_tiny.dir, out, calib=[tmp_path / "broken.mp4"])
    with pytest.raises(ValueError, match="not both"):
        actengine.convert(act_tiny.dir, out, calib=[act_tiny.observation(0), act_tiny.dir])
    with pytest.raises(TypeError, match=r"calib\[1\] is a int"):
        actengine.convert(act_tiny.dir, out, calib=[act_tiny.dir, 3])
    with pytest.raises(TypeError, match="in a list; got one dict"):
        actengine.convert(act_tiny.dir, out, calib=act_tiny.observation(0))
    assert not out.exists()
