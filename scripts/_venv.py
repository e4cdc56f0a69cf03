"""The project's Python venv (third_party/pyenv, made by scripts/setup.sh) for
scripts whose packages the current interpreter lacks."""
import os
import pathlib
import sys

VENV_PYTHON = pathlib.Path(__file__).resolve().parent.parent / "third_party" / "pyenv" / "bin" / "python"


def reexec_in_venv(script):
    """Run `script` again, with the same arguments, under the venv's interpreter
    (this process is replaced). Returns when there is no venv or this already is
    that rerun."""
    if VENV_PYTHON.is_file() and not os.environ.get("DREAMPOLICY_IN_PYENV"):
        os.environ["DREAMPOLICY_IN_PYENV"] = "1"
        os.execv(str(VENV_PYTHON), [str(VENV_PYTHON), script, *sys.argv[1:]])
