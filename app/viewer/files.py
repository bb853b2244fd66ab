"""Opening scenes and volumes: by path (drag and drop, the file dialog; a folder is a TIFF stack or a
DICOM series), the built-in volumes and
the datasets in ../shared/datasets; and the file dialog itself, the system's own through
portable-file-dialogs where it has one (zenity, kdialog), else a small browser drawn with ImGui."""
from __future__ import annotations

import json
import os
import shutil
from dataclasses import replace
from pathlib import Path

from radiance_probes.paths import ASSETS_DIR
from radiance_probes.io.scene_file import Scene, VolumeSpec, load_scene
from radiance_probes.io.volume import VOLUME_SUFFIXES, is_volume_path
from radiance_probes.io.volume_formats import has_suffix

# The open dialog's filter: every suffix load_volume reads (folders are opened with "Open folder").
DIALOG_PATTERNS = " ".join(["*.json"] + [f"*{s}" for s in VOLUME_SUFFIXES])
SCENE_SUFFIXES = (".json",)
DIALOG_TOOLS = ("zenity", "kdialog", "qarma", "matedialog")


def datasets_dirs() -> list[Path]:
    """../shared/datasets beside the checkout and beside the working directory, where present."""
    candidates = [ASSETS_DIR.parent.parent / "shared" / "datasets", Path.cwd().parent / "shared" / "datasets"]
    out: list[Path] = []
    for c in candidates:
        if c.is_dir() and c.resolve() not in [o.resolve() for o in out]:
            out.append(c)
    return out


def datasets() -> list[Path]:
    return sorted(p for d in datasets_dirs() for p in d.iterdir()
                  if p.is_file() and has_suffix(p, VOLUME_SUFFIXES))


def bundled_scene_for(volume_path: Path) -> Path | None:
    """The scene in assets/scenes made for this volume file (same file name), if any."""
    for scene_file in sorted((ASSETS_DIR / "scenes").glob("*.json")):
        try:
            volume = json.loads(scene_file.read_text()).get("volume", {})
        except (OSError, ValueError):
            continue
        if isinstance(volume, dict) and Path(str(volume.get("path", ""))).name == volume_path.name:
            return scene_file
    return None


def scene_for_path(path: str | Path, current: Scene) -> tuple[Scene, str | None]:
    """A scene file as it is; a volume file with its bundled scene where there is one, else in
    the current scene (its transfer function, light and probes kept); a folder is a volume (a TIFF
    stack or a DICOM series). Returns (scene, scene path)."""
    p = Path(path).expanduser()
    if p.suffix.lower() in SCENE_SUFFIXES and not p.is_dir():
        return load_scene(p), str(p)
    bundled = bundled_scene_for(p)
    if bundled is not None:
        scene = load_scene(bundled)
        return scene.replace(volume=replace(scene.volume, path=str(p.resolve()))), None
    if not is_volume_path(p):
        raise ValueError(f"{p}: not a scene (.json) or a volume ({', '.join(VOLUME_SUFFIXES)}, "
                         "or a folder of TIFF or DICOM slices)")
    return current.replace(volume=VolumeSpec(path=str(p.resolve()), builtin=None)), None


def builtin_scene(name: str, size: tuple[int, int, int], current: Scene) -> Scene:
    return current.replace(volume=VolumeSpec(builtin=name, size=tuple(size)))


FILE_DIALOGS = ("auto", "builtin")


def native_dialogs_available(dialog: str = "auto") -> bool:
    """A system dialog tool is installed, and `dialog` (``view --file-dialog``) is not "builtin"."""
    if dialog not in FILE_DIALOGS:
        raise ValueError(f"file dialog: expected one of {', '.join(FILE_DIALOGS)}, got {dialog!r}")
    if dialog == "builtin":
        return False
    return any(shutil.which(tool) for tool in DIALOG_TOOLS)


class FileDialogs:
    """Asynchronous open/save dialogs; the viewer polls them once a frame."""

    def __init__(self, on_open, start_dir: str | None = None, dialog: str = "auto"):
        self.on_open = on_open            # on_open(path)
        self.native = native_dialogs_available(dialog)
        self.pending = None               # a portable_file_dialogs dialog in flight
        self.browser_open = False
        self.browser_dir = Path(start_dir or os.getcwd())

    def open_dialog(self) -> None:
        if self.native:
            from imgui_bundle import portable_file_dialogs as pfd
            self.pending = pfd.open_file("Open a scene or a volume", str(self.browser_dir),
                                         ["Scenes and volumes", DIALOG_PATTERNS,
                                          "All files", "*"])
        else:
            self.browser_open = True

    def open_folder_dialog(self) -> None:
        """A folder as a volume: a TIFF stack or a DICOM series (the built-in browser's "Open this
        folder" where there is no system dialog)."""
        if self.native:
            from imgui_bundle import portable_file_dialogs as pfd
            self.pending = pfd.select_folder("Open a TIFF or DICOM folder", str(self.browser_dir))
        else:
            self.browser_open = True

    def poll(self) -> None:
        if self.pending is not None and self.pending.ready(0):
            chosen = self.pending.result()   # a list of files, or a folder's path
            self.pending = None
            if isinstance(chosen, str):
                chosen = [chosen] if chosen else []
            if chosen:
                self.on_open(chosen[0])

    def entries(self) -> list[Path]:
        """The browser's folder: sub-folders, then scenes and volumes."""
        try:
            items = list(self.browser_dir.iterdir())
        except OSError:
            return []
        folders = sorted(p for p in items if p.is_dir() and not p.name.startswith("."))
        files = sorted(p for p in items if p.is_file()
                       and has_suffix(p, VOLUME_SUFFIXES + SCENE_SUFFIXES))
        return folders + files
