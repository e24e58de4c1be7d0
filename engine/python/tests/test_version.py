"""One version number: the project VERSION of CMakeLists.txt is the library's (actengine::version(),
compiled in), the module's actengine.__version__ and the wheel's (setup.py reads the same line)."""

import re
from pathlib import Path

import actengine

ROOT = Path(__file__).resolve().parents[3]


def project_version():
    found = re.search(r"project\(\s*actengine\s+VERSION\s+([0-9][0-9.]*)", (ROOT / "CMakeLists.txt").read_text())
    assert found, "no project VERSION in CMakeLists.txt"
    return found.group(1)


def test_version_is_the_projects():
    assert actengine.__version__ == project_version()


def test_setup_py_reads_the_same_version():
    source = (ROOT / "setup.py").read_text()
    namespace = {"__file__": str(ROOT / "setup.py")}
    # setup.py's own reader, without running setup(): everything above the call.
    exec(compile(source.split("\nsetup(", 1)[0], str(ROOT / "setup.py"), "exec"), namespace)
    assert namespace["project_version"]() == project_version()
