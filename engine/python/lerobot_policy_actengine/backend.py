"""A PEP 517 build backend for the pure-Python wheel lerobot_policy_actengine (pyproject.toml says why
not setuptools). Writes the wheel with the standard library only; the version is the project VERSION
of the repository's CMakeLists.txt, and the wheel requires that same actengine version."""

import base64
import hashlib
import io
import re
import tarfile
import zipfile
from pathlib import Path

NAME = "lerobot_policy_actengine"
HERE = Path(__file__).resolve().parent
PACKAGE = HERE / NAME
SUMMARY = "LeRobot policy plugin: run an actengine .actb blob with LeRobot's commands (--policy.path)"


def _version():
    for candidate in (HERE.parents[2] / "CMakeLists.txt", HERE / "VERSION"):
        if candidate.exists():
            text = candidate.read_text()
            found = re.search(r"project\(\s*actengine\s+VERSION\s+([0-9][0-9.]*)", text) or re.fullmatch(r"\s*([0-9][0-9.]*)\s*", text)
            if found:
                return found.group(1)
    raise RuntimeError("no actengine version: neither the repository's CMakeLists.txt nor a VERSION file")


def _metadata(version):
    return (f"Metadata-Version: 2.1\nName: {NAME}\nVersion: {version}\nSummary: {SUMMARY}\n"
            f"Requires-Python: >=3.11\nRequires-Dist: actengine=={version}\nRequires-Dist: numpy\n")


def _sources():
    return sorted(p for p in PACKAGE.rglob("*.py") if "__pycache__" not in p.parts)


def _record_line(name, data):
    digest = base64.urlsafe_b64encode(hashlib.sha256(data).digest()).rstrip(b"=").decode()
    return f"{name},sha256={digest},{len(data)}"


def _write_wheel(directory, files):
    version = _version()
    dist_info = f"{NAME}-{version}.dist-info"
    files = dict(files)
    files[f"{dist_info}/METADATA"] = _metadata(version).encode()
    files[f"{dist_info}/WHEEL"] = b"Wheel-Version: 1.0\nGenerator: lerobot_policy_actengine backend\nRoot-Is-Purelib: true\nTag: py3-none-any\n"
    files[f"{dist_info}/top_level.txt"] = f"{NAME}\n".encode()
    files[f"{dist_info}/entry_points.txt"] = f"[console_scripts]\nactengine-package = {NAME}.package:main\n".encode()
    record = [_record_line(name, data) for name, data in files.items()] + [f"{dist_info}/RECORD,,"]
    files[f"{dist_info}/RECORD"] = ("\n".join(record) + "\n").encode()
    wheel_name = f"{NAME}-{version}-py3-none-any.whl"
    with zipfile.ZipFile(Path(directory) / wheel_name, "w", zipfile.ZIP_DEFLATED) as wheel:
        for name, data in files.items():
            wheel.writestr(zipfile.ZipInfo(name, date_time=(1980, 1, 1, 0, 0, 0)), data)
    return wheel_name


def build_wheel(wheel_directory, config_settings=None, metadata_directory=None):
    return _write_wheel(wheel_directory, {p.relative_to(HERE).as_posix(): p.read_bytes() for p in _sources()})


def build_editable(wheel_directory, config_settings=None, metadata_directory=None):
    """A .pth file pointing at this folder: edits to the sources take effect without reinstalling."""
    return _write_wheel(wheel_directory, {f"{NAME}.pth": f"{HERE}\n".encode()})


def build_sdist(sdist_directory, config_settings=None):
    version = _version()
    base = f"{NAME}-{version}"
    name = f"{base}.tar.gz"
    with tarfile.open(Path(sdist_directory) / name, "w:gz") as sdist:
        members = {"pyproject.toml": (HERE / "pyproject.toml").read_bytes(), "backend.py": (HERE / "backend.py").read_bytes(),
                   "VERSION": f"{version}\n".encode(), "PKG-INFO": _metadata(version).encode()}
        members.update({p.relative_to(HERE).as_posix(): p.read_bytes() for p in _sources()})
        for path, data in members.items():
            info = tarfile.TarInfo(f"{base}/{path}")
            info.size = len(data)
            sdist.addfile(info, io.BytesIO(data))
    return name


def get_requires_for_build_wheel(config_settings=None):
    return []


get_requires_for_build_editable = get_requires_for_build_sdist = get_requires_for_build_wheel
