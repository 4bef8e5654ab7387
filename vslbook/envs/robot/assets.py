"""Model files of the robot tasks: read from the installed fancy-gym 0.3.0 wheel, never copied.

fancy-gym (MIT) is installed with ``pip install --no-deps fancy-gym==0.3.0`` by the setup
(its Python code does not import on gymnasium ≥ 1.0 and is never imported here); this module
finds its package directory with :func:`importlib.util.find_spec`, which locates a package
without executing it, and reads the XML and mesh files from there. What MuJoCo 3.17 rejects
is patched in memory (:func:`load_spec`): relative ``include``/``meshdir``/``texturedir``
paths become absolute so the XML can be compiled from a string, and each task passes its
own textual fixes (e.g. dropping ``collision="all"``).
"""

from __future__ import annotations

import importlib.util
import re
from collections.abc import Iterable
from pathlib import Path

import mujoco

FANCY_GYM = "fancy-gym==0.3.0"
INSTALL_HINT = f"install it with: pip install --no-deps {FANCY_GYM}"


def fancy_gym_dir() -> Path:
    """The installed ``fancy_gym`` package directory (not imported), or a clear error."""
    spec = importlib.util.find_spec("fancy_gym")
    if spec is None or not spec.submodule_search_locations:
        raise FileNotFoundError(f"the robot tasks read model files from fancy-gym; {INSTALL_HINT}")
    return Path(next(iter(spec.submodule_search_locations)))


def asset_path(relative: str) -> Path:
    """Path of a file under ``fancy_gym/envs/mujoco/`` (``reacher/assets/reacher_5links.xml``)."""
    path = fancy_gym_dir() / "envs" / "mujoco" / relative
    if not path.is_file():
        raise FileNotFoundError(f"{path} is missing from the installed fancy-gym; {INSTALL_HINT}")
    return path


_PATH_ATTR = re.compile(r'\b(meshdir|texturedir)\s*=\s*"([^"]*)"')


def absolutize(xml: str, base: Path) -> str:
    """Rewrite relative ``meshdir``/``texturedir`` attributes against ``base``.

    ``<include file=...>`` targets are read and inlined recursively (their own relative
    directories resolved against their directory), so the result compiles from a string.
    Asset ``file`` attributes stay relative to these directories, as MuJoCo reads them.
    """

    def include(match: re.Match[str]) -> str:
        target = (base / match.group(1)).resolve()
        inner = re.sub(r"<!--.*?-->", "", target.read_text(encoding="utf-8"), flags=re.S)
        inner = re.sub(r"<\?xml[^>]*\?>", "", inner).strip()
        # MuJoCo inserts the children of the included file's root element.
        # (whatever the root is called: one 0.3.0 file spells it "mujocoinclue").
        inner = re.sub(r"^<[A-Za-z_]\w*\b[^>]*>", "", inner)
        inner = re.sub(r"</[A-Za-z_]\w*>\s*$", "", inner)
        return absolutize(inner, target.parent)

    xml = re.sub(r'<include\s+file\s*=\s*"([^"]*)"\s*/>', include, xml)

    def fix(match: re.Match[str]) -> str:
        key, value = match.group(1), match.group(2)
        if not value or Path(value).is_absolute():
            return match.group(0)
        return f'{key}="{(base / value).resolve()}"'

    return _PATH_ATTR.sub(fix, xml)


def read_xml(relative: str, patches: Iterable[tuple[str, str]] = ()) -> str:
    """The XML of a fancy-gym model with includes inlined, paths absolute and ``patches``
    applied (each ``(old, new)`` must occur, so a changed file fails loudly)."""
    path = asset_path(relative)
    xml = path.read_text(encoding="utf-8")
    for old, new in patches:
        if old not in xml:
            raise ValueError(f"patch target {old!r} not found in {path}")
        xml = xml.replace(old, new)
    xml = absolutize(xml, path.parent)
    # Without meshdir/texturedir MuJoCo reads assets relative to the model file; a string
    # has no file, so name the model's directory explicitly.
    for key in ("meshdir", "texturedir"):
        if f"{key}=" not in xml:
            xml = re.sub(r"<compiler\b", f'<compiler {key}="{path.parent}"', xml, count=1)
            if f"{key}=" not in xml:
                xml = re.sub(
                    r"(<mujoco\b[^>]*>)", rf'\1<compiler {key}="{path.parent}"/>', xml, count=1
                )
    return xml


def load_spec(relative: str, patches: Iterable[tuple[str, str]] = ()) -> mujoco.MjSpec:
    """An editable :class:`mujoco.MjSpec` of a fancy-gym model (see :func:`read_xml`)."""
    return mujoco.MjSpec.from_string(read_xml(relative, patches))


def load_model(relative: str, patches: Iterable[tuple[str, str]] = ()) -> mujoco.MjModel:
    """A compiled :class:`mujoco.MjModel` of a fancy-gym model (see :func:`read_xml`)."""
    return load_spec(relative, patches).compile()
