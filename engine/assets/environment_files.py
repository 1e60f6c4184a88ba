"""HDR environment files (.hdr Radiance RGBE, .exr OpenEXR) and the built-in procedural ones.

`resolve_environment("studio")`, `resolve_environment("~/hdris/venice_sunset_1k.hdr")` or
`resolve_environment(CAPTURE_FOLDER)` (the lighting its photos were taken in) is the one entry point the command line and the app use; `load_environment_file` reads a file only.

Every failure is an `EnvironmentLoadError` whose message names the file and says what to do.
Non-finite or negative texels do not fail the load: they are repaired (NaN -> 0, +Inf -> the
largest finite value, negative -> 0) with a warning on the "lirm" logger, because a handful of bad
texels in an otherwise fine HDRI should not stop a preview.

Reading .hdr: OpenCV's RGBE decoder (cv2.imdecode, float32 BGR). It is strict: a file cut short
anywhere in its pixel data (even by one byte) or with corrupt run-length data decodes to nothing
rather than a partly-black image (checked with OpenCV 5.0; tests/engine/assets holds it to that),
so a failed decode after a valid header is reported as truncated or corrupt. The header is parsed
here first so that non-HDR files, odd orientations and non-2:1 images get a precise message
before any pixels are decoded.

Reading .exr: the OpenEXR 3.x `OpenEXR.File` API. R, G, B (or a single Y, broadcast to grey) of the
first part that has them; alpha and other channels are ignored. Resolution is kept as stored: files
are not resampled (the renderer builds its cubemaps from any size).
"""

from __future__ import annotations

import logging
import math
import threading
from pathlib import Path

import numpy as np

from lirm.engine.errors import EnvironmentLoadError
from lirm.renderer.environment import Environment
from lirm.renderer.procedural_environments import PROCEDURAL_ENVIRONMENTS, make_procedural_environment

log = logging.getLogger("lirm")

BUILTIN_ENVIRONMENTS: tuple[str, ...] = tuple(PROCEDURAL_ENVIRONMENTS)
SUPPORTED_SUFFIXES: tuple[str, ...] = (".hdr", ".exr")
MIN_ASPECT, MAX_ASPECT = 1.9, 2.1  # equirectangular is 2:1; allow off-by-a-few-pixels exports

_HDR_MAGIC = (b"#?RADIANCE", b"#?RGBE")
_EXR_MAGIC = b"\x76\x2f\x31\x01"
_MAX_HEADER_BYTES = 64 * 1024
_WHAT_TO_PASS = "pass an equirectangular (2:1) .hdr or .exr file"
_BUILTIN_HINT = f"or use one of the built-in names: {', '.join(BUILTIN_ENVIRONMENTS)}"
_cv2_log_lock = threading.Lock()


def resolve_environment(name_or_path: str | Path, width: int = 1024) -> Environment:
    """A built-in environment by name (rendered at `width`), else the .hdr/.exr file at that path.

    A name that is both a built-in and a file is taken as the built-in unless passed as a Path.
    """
    if isinstance(name_or_path, str) and name_or_path.strip().lower() in PROCEDURAL_ENVIRONMENTS:
        return make_procedural_environment(name_or_path.strip().lower(), width=width)
    path = Path(name_or_path).expanduser()
    if path.is_dir() and (path / "capture.json").is_file():
        return _capture_lighting(path)
    if not path.exists():
        raise EnvironmentLoadError(
            f"environment {str(name_or_path)!r} is neither a built-in name nor an existing file: "
            f"{_WHAT_TO_PASS}, {_BUILTIN_HINT}"
        )
    return load_environment_file(path)


def _capture_lighting(capture: Path) -> Environment:
    """A capture folder stands for the lighting its photos were taken in ("as photographed")."""
    from lirm.engine.lighting.capture_lighting import ENVIRONMENT_NAME, LIGHTING_FOLDER, PANORAMA_FILE, missing_lighting_reason

    path = capture / LIGHTING_FOLDER / PANORAMA_FILE
    if not path.is_file():
        reason = missing_lighting_reason(capture)
        raise EnvironmentLoadError(f"{capture}: this capture has no lighting estimate ({reason}); pass a built-in "
                                   f"environment or an HDRI instead")
    environment = load_environment_file(path)
    environment.name = ENVIRONMENT_NAME
    return environment


def load_environment_file(path: str | Path) -> Environment:
    """Linear float32 RGB radiance (H, W, 3), row 0 = zenith, from an equirectangular .hdr or .exr."""
    path = Path(path).expanduser()
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise EnvironmentLoadError(
            f"{path}: unsupported environment format {suffix or '(no suffix)'!r}; {_WHAT_TO_PASS}"
            " (convert other formats with a tool that keeps HDR values)"
        )
    data = _read_bytes(path)
    if data.startswith(_EXR_MAGIC):  # by content: a renamed .exr still loads
        rgb = _decode_exr(path)
    elif data.startswith(_HDR_MAGIC):
        rgb = _decode_hdr(path, data)
    else:
        raise EnvironmentLoadError(
            f"{path}: not a {'Radiance HDR' if suffix == '.hdr' else 'OpenEXR'} file "
            f"({_sniff(data)}); {_WHAT_TO_PASS} holding linear HDR values, or re-download it"
        )
    _check_aspect(path, rgb.shape[1], rgb.shape[0])
    rgb = _sanitize(rgb, path)
    try:
        return Environment(rgb, name=path.stem)
    except ValueError as err:  # e.g. too few pixels to be a panorama
        raise EnvironmentLoadError(f"{path}: {err}; {_WHAT_TO_PASS}") from None


# --------------------------------------------------------------------------------------------
# Radiance RGBE
# --------------------------------------------------------------------------------------------


def _decode_hdr(path: Path, data: bytes) -> np.ndarray:
    width, height, pixels_at = _parse_hdr_header(path, data)
    _check_aspect(path, width, height)
    # The smallest possible new-style RLE scanline: 4 marker bytes + per channel one 2-byte run per
    # 127 pixels. Less data than that cannot be a whole image, however well it compresses.
    if 8 <= width <= 0x7FFF:
        min_bytes = height * (4 + 4 * 2 * math.ceil(width / 127))
    else:
        min_bytes = height * width * 4  # flat RGBE
    if len(data) - pixels_at < min_bytes:
        raise EnvironmentLoadError(
            f"{path}: truncated: the header promises {width}x{height} pixels but only "
            f"{len(data) - pixels_at} bytes of pixel data follow; re-download it"
        )

    import cv2

    buf = np.frombuffer(data, dtype=np.uint8)
    # OpenCV logs its own decode error to stderr; the user gets ours instead.
    with _cv2_log_lock:
        level = cv2.utils.logging.getLogLevel()
        cv2.utils.logging.setLogLevel(cv2.utils.logging.LOG_LEVEL_SILENT)
        try:
            bgr = cv2.imdecode(buf, cv2.IMREAD_UNCHANGED)
        except cv2.error:
            bgr = None
        finally:
            cv2.utils.logging.setLogLevel(level)
    if bgr is None or bgr.size == 0:
        raise EnvironmentLoadError(
            f"{path}: the pixel data is truncated or corrupt (an incomplete download?); re-download it"
        )
    if bgr.dtype != np.float32 or bgr.ndim != 3 or bgr.shape[2] != 3 or bgr.shape[:2] != (height, width):
        raise EnvironmentLoadError(
            f"{path}: decoded as {bgr.dtype} {bgr.shape}, not {width}x{height} float RGB; "
            f"re-save it as a standard Radiance .hdr or {_WHAT_TO_PASS}"
        )
    return np.ascontiguousarray(bgr[..., ::-1])


def _parse_hdr_header(path: Path, data: bytes) -> tuple[int, int, int]:
    """(width, height, offset of the pixel data), for the standard "-Y H +X W" orientation only."""
    end = data.find(b"\n\n", 0, _MAX_HEADER_BYTES)
    if end < 0:
        raise EnvironmentLoadError(f"{path}: the Radiance header never ends (truncated or corrupt); re-download it")
    header = data[:end].decode("latin-1").split("\n")
    formats = [line.split("=", 1)[1].strip() for line in header if line.startswith("FORMAT=")]
    if formats and formats[-1] != "32-bit_rle_rgbe":
        raise EnvironmentLoadError(
            f"{path}: Radiance format {formats[-1]!r} is not supported (only 32-bit_rle_rgbe); "
            f"re-save it as RGB, or {_WHAT_TO_PASS}"
        )
    line_end = data.find(b"\n", end + 2, end + 2 + 256)
    if line_end < 0:
        raise EnvironmentLoadError(f"{path}: the image size line is missing (truncated or corrupt); re-download it")
    size_line = data[end + 2 : line_end].decode("latin-1").split()
    if len(size_line) != 4 or not size_line[1].isdigit() or not size_line[3].isdigit():
        raise EnvironmentLoadError(f"{path}: unreadable image size line {' '.join(size_line)!r}; re-download it")
    if (size_line[0], size_line[2]) != ("-Y", "+X"):
        raise EnvironmentLoadError(
            f"{path}: image orientation '{size_line[0]} {size_line[2]}' is not supported "
            "(only the standard '-Y H +X W'); re-save it with an image editor"
        )
    height, width = int(size_line[1]), int(size_line[3])
    if width <= 0 or height <= 0:
        raise EnvironmentLoadError(f"{path}: the header gives an empty {width}x{height} image; re-download it")
    return width, height, line_end + 1


# --------------------------------------------------------------------------------------------
# OpenEXR
# --------------------------------------------------------------------------------------------


def _decode_exr(path: Path) -> np.ndarray:
    import OpenEXR

    broken = f"{path}: cannot be read as OpenEXR: the file is truncated or corrupt; re-download it"
    try:
        exr = OpenEXR.File(str(path), separate_channels=True)
        parts = [(exr.header(i), exr.channels(i)) for i in range(len(exr.parts))]
    except Exception as err:  # the binding raises RuntimeError/ValueError/TypeError variously
        raise EnvironmentLoadError(f"{broken} ({err})") from None
    # A pixel-data read error is only printed by the binding, which then returns a File with no
    # parts (or channels without pixels) instead of raising.
    if not parts or any(ch.pixels is None for _, chans in parts for ch in chans.values()):
        raise EnvironmentLoadError(broken)

    for header, channels in parts:
        names = set(channels)
        if {"RY", "BY"} & names:
            raise EnvironmentLoadError(
                f"{path}: luminance/chroma (Y, RY, BY) EXR is not supported; re-save it as RGB EXR"
            )
        if {"R", "G", "B"} <= names:
            planes = [channels[c] for c in ("R", "G", "B")]
        elif "Y" in names:
            planes = [channels["Y"]] * 3
        else:
            continue
        return _place_in_display_window(path, header, [_exr_plane(path, ch) for ch in planes])

    all_names = sorted({n for _, ch in parts for n in ch})
    raise EnvironmentLoadError(
        f"{path}: no R, G, B (or Y) channels, only {', '.join(all_names) or 'none'}; "
        "re-export the environment with plain RGB channels"
    )


def _exr_plane(path: Path, channel) -> np.ndarray:
    if (channel.xSampling, channel.ySampling) != (1, 1):
        raise EnvironmentLoadError(
            f"{path}: subsampled channels are not supported; re-save it as full-resolution RGB EXR"
        )
    pixels = np.asarray(channel.pixels)
    if pixels.dtype.kind != "f":
        raise EnvironmentLoadError(
            f"{path}: channel {channel.name!r} holds {pixels.dtype} integers, not radiance; "
            "re-export it as half or float RGB"
        )
    return pixels.astype(np.float32, copy=False)


def _place_in_display_window(path: Path, header: dict, planes: list[np.ndarray]) -> np.ndarray:
    rgb = np.stack(planes, axis=-1)
    data_lo, data_hi = (np.asarray(a, dtype=np.int64) for a in header["dataWindow"])
    disp_lo, disp_hi = (np.asarray(a, dtype=np.int64) for a in header.get("displayWindow", header["dataWindow"]))
    if np.array_equal(data_lo, disp_lo) and np.array_equal(data_hi, disp_hi):
        return rgb
    # Pixels outside the data window are black by the EXR spec; the image is the display window.
    w, h = (disp_hi - disp_lo + 1).tolist()
    if w <= 0 or h <= 0:
        raise EnvironmentLoadError(f"{path}: the EXR display window is empty; re-export it")
    out = np.zeros((h, w, 3), dtype=np.float32)
    x0, y0 = (data_lo - disp_lo).tolist()
    ys0, xs0 = max(0, -y0), max(0, -x0)
    ye, xe = min(h, y0 + rgb.shape[0]), min(w, x0 + rgb.shape[1])
    if ye > max(y0, 0) and xe > max(x0, 0):
        out[max(y0, 0) : ye, max(x0, 0) : xe] = rgb[ys0 : ys0 + ye - max(y0, 0), xs0 : xs0 + xe - max(x0, 0)]
    return out


# --------------------------------------------------------------------------------------------
# Shared checks
# --------------------------------------------------------------------------------------------


def _read_bytes(path: Path) -> bytes:
    if not path.exists():
        raise EnvironmentLoadError(f"{path}: file not found; {_WHAT_TO_PASS}, {_BUILTIN_HINT}")
    if path.is_dir():
        raise EnvironmentLoadError(f"{path}: is a folder, not a file; {_WHAT_TO_PASS}")
    try:
        data = path.read_bytes()
    except OSError as err:
        raise EnvironmentLoadError(f"{path}: cannot be read ({err.strerror}); check its permissions") from None
    if not data:
        raise EnvironmentLoadError(f"{path}: the file is empty (0 bytes), an interrupted download?; re-download it")
    return data


def _sniff(data: bytes) -> str:
    if data.startswith(b"\x89PNG"):
        return "it is a PNG image, 8 or 16-bit, which cannot hold HDR light"
    if data.startswith(b"\xff\xd8\xff"):
        return "it is a JPEG image, 8-bit, which cannot hold HDR light"
    if data[:4] in (b"II*\x00", b"MM\x00*"):
        return "it is a TIFF image"
    if data.startswith(b"RIFF") and data[8:12] == b"WEBP":
        return "it is a WebP image"
    return "unrecognised contents"


def _check_aspect(path: Path, width: int, height: int) -> None:
    ratio = width / height if height else math.inf
    if not MIN_ASPECT <= ratio <= MAX_ASPECT:
        raise EnvironmentLoadError(
            f"{path}: {width}x{height} is not an equirectangular panorama (width:height must be 2:1, "
            f"got {ratio:.2f}:1); {_WHAT_TO_PASS} (cubemaps and cropped photos are not supported)"
        )


def _sanitize(rgb: np.ndarray, path: Path) -> np.ndarray:
    rgb = np.asarray(rgb, dtype=np.float32)
    nan = np.isnan(rgb)
    posinf = np.isposinf(rgb)
    negative = rgb < 0  # includes -inf
    n_nan, n_inf, n_neg = int(nan.sum()), int(posinf.sum()), int(negative.sum())
    if not (n_nan or n_inf or n_neg):
        return rgb
    rgb = rgb.copy()
    finite = rgb[np.isfinite(rgb)]
    largest = float(finite.max()) if finite.size else 0.0
    rgb[nan] = 0.0
    rgb[posinf] = max(largest, 0.0)
    rgb[negative] = 0.0
    log.warning(
        "%s: repaired %d NaN, %d +Inf (set to %.4g) and %d negative texel values (set to 0)",
        path, n_nan, n_inf, largest, n_neg,
    )
    return rgb
