"""The environment a capture was photographed in, estimated from its own photos' backgrounds.

Every posed photo's pixels outside the object's mask are rays that saw the surroundings. Each is
followed to a proxy of the surroundings: the support plane the object stands on (or hangs from), when
the capture found one, and a sphere around the object beyond it (radius: `proxy_radius` x the
cameras' median distance); the direction from the object's centre to where it lands gets the pixel's
radiance (the camera's tone curve inverted, camera_response.py). So the table under the object is
placed where the object sees it (on a sphere alone a near floor lands 20 degrees too high: the
cameras see it from above, the object from beside), and far surroundings exactly; averaging over all
photos gives a panorama in the capture's world frame (+Z up, the renderer's environment frame with
rotation 0).

What the photos did not see (usually the sky or ceiling above them, whence most light comes) is
filled smoothly from what they did see (push-pull over a pyramid), and marked as unseen in
`observed`; the refinement's inverse rendering is where the object's own shading can say more.
LDR clipping is explicit: a pixel at the top of the 8-bit range is a lower bound of the radiance it
saw, and `clipped` holds the share of such pixels per direction, so a bright source is not mistaken
for a dim grey one without saying so.
"""

from __future__ import annotations

import json
from dataclasses import asdict, dataclass
from pathlib import Path

import cv2
import numpy as np

from lirm.renderer.environment import Environment, direction_to_equirect_uv
from lirm.renderer.tonemap import tonemap

from ..io.atomic_files import atomic_write, atomic_write_json
from ..io.images import write_png
from .camera_response import RESPONSES, display_to_radiance

LIGHTING_FOLDER = "lighting"
PANORAMA_FILE = "as_photographed.hdr"
PICTURE_FILE = "as_photographed.png"
INFO_FILE = "lighting.json"
OBSERVED_FILE = "observed.npz"  # per texel: photo pixels that landed there, and the share clipped
ENVIRONMENT_NAME = "as photographed"


@dataclass(frozen=True)
class CaptureLightingConfig:
    width: int = 128  # panorama width; height = width / 2 (2.8 degree texels: lighting, not a backdrop)
    proxy_radius: float = 2.0  # times the cameras' median distance from the object
    mask_margin_px: int = 4  # background pixels this close to the object are left out (its blurred edge)
    clip_level: float = 250.0 / 255.0  # a display value at or above this in any channel is clipped
    response: str = "aces"  # camera_response.RESPONSES
    pixels_per_photo: int = 60_000  # a regular subsample of each photo's background

    def __post_init__(self) -> None:
        if self.width < 16 or self.width % 2:
            raise ValueError("the lighting panorama needs an even width of at least 16")
        if self.proxy_radius <= 1.0:
            raise ValueError("proxy_radius must be more than 1 (the sphere must enclose the cameras)")


@dataclass
class CaptureLighting:
    environment: Environment  # the filled panorama, linear radiance
    observed: np.ndarray  # (H, W) photo pixels that landed in each texel (0: filled, not seen)
    clipped: np.ndarray  # (H, W) share of those that were clipped (a lower bound of the radiance there)
    photos_used: int
    config: CaptureLightingConfig
    on_support_plane: bool = False  # the backgrounds were placed on the capture's support plane (and the sphere)

    @property
    def seen_fraction(self) -> float:
        """Share of the sphere's solid angle that some photo saw."""
        _, solid_angle = self.environment.texel_directions()
        return float(solid_angle[self.observed > 0].sum() / solid_angle.sum())

    @property
    def clipped_fraction(self) -> float:
        _, solid_angle = self.environment.texel_directions()
        seen = self.observed > 0
        return float((solid_angle * self.clipped)[seen].sum() / max(solid_angle[seen].sum(), 1e-12))

    def save(self, capture_root: str | Path) -> Path:
        folder = Path(capture_root) / LIGHTING_FOLDER
        folder.mkdir(parents=True, exist_ok=True)
        write_hdr(folder / PANORAMA_FILE, self.environment)
        write_png(folder / PICTURE_FILE, lighting_picture(self))

        def write_observed(tmp: Path) -> None:
            with open(tmp, "wb") as handle:
                np.savez_compressed(handle, observed=self.observed.astype(np.float32), clipped=self.clipped.astype(np.float32))
        atomic_write(folder / OBSERVED_FILE, write_observed)
        atomic_write_json(folder / INFO_FILE, {
            "photos_used": self.photos_used, "seen_fraction": round(self.seen_fraction, 4),
            "clipped_fraction_of_seen": round(self.clipped_fraction, 4), "config": asdict(self.config),
            "proxy": "support plane and sphere" if self.on_support_plane else "sphere",
            "note": "directions no photo saw are filled smoothly from those they did (not measured)",
        })
        return folder / PANORAMA_FILE


def write_hdr(path: Path, environment: Environment) -> Path:
    """An environment as a Radiance .hdr file, atomically."""
    ok, encoded = cv2.imencode(".hdr", np.ascontiguousarray(environment.radiance[:, :, ::-1], dtype=np.float32))
    if not ok:
        raise OSError(f"{path}: OpenCV could not encode the panorama")
    return atomic_write(path, lambda tmp: tmp.write_bytes(encoded.tobytes()))


def lighting_picture(lighting: CaptureLighting, scale: int = 4) -> np.ndarray:
    """The panorama tone-mapped (exposed for its seen part), with unseen directions hatched and
    clipped ones outlined in red, as uint8 RGB."""
    radiance = lighting.environment.radiance
    seen = lighting.observed > 0
    key = np.percentile(radiance[seen].mean(-1), 50) if seen.any() else max(float(radiance.mean()), 1e-6)
    picture = tonemap(radiance * (0.18 / max(key, 1e-6)))
    h, w = seen.shape
    big = cv2.resize((picture * 255).astype(np.uint8), (w * scale, h * scale), interpolation=cv2.INTER_NEAREST)
    unseen = cv2.resize((~seen).astype(np.uint8), (w * scale, h * scale), interpolation=cv2.INTER_NEAREST) > 0
    yy, xx = np.mgrid[0:h * scale, 0:w * scale]
    hatch = unseen & (((xx + yy) // 3) % 4 == 0)
    big[hatch] = (big[hatch] * 0.4 + 255 * 0.6).astype(np.uint8)
    clipped = cv2.resize((lighting.clipped > 0.5).astype(np.uint8), (w * scale, h * scale), interpolation=cv2.INTER_NEAREST)
    edges = cv2.morphologyEx(clipped, cv2.MORPH_GRADIENT, np.ones((3, 3), np.uint8)) > 0
    big[edges] = (230, 40, 40)
    return big


def estimate_capture_lighting(images: dict, masks: dict, cameras: dict, config: CaptureLightingConfig = CaptureLightingConfig(),
                              cancel=None, support_plane: tuple[np.ndarray, float] | None = None) -> CaptureLighting:
    """`images` frame -> RGB(A) uint8 working image, `masks` frame -> uint8 (255 = object), `cameras`
    frame -> Camera in the normalised world (object at the origin). `support_plane` (unit normal
    toward the cameras, offset: n . x = offset, in the same world; normalize.Normalization.plane):
    background rays that meet it land there instead of on the sphere."""
    frames = [f for f in sorted(cameras) if f in images and f in masks]
    if not frames:
        raise ValueError("no posed photo with a mask to estimate the lighting from")
    radius = proxy_radius_of({f: cameras[f] for f in frames}, config)
    h, w = config.width // 2, config.width
    total = np.zeros((h * w, 3))
    count = np.zeros(h * w)
    clipped = np.zeros(h * w)
    used = 0
    for f in frames:
        if cancel is not None and cancel():
            raise InterruptedError("cancelled while estimating the capture lighting")
        texel, display = background_samples(images[f], masks[f], cameras[f], config, radius, support_plane)
        if len(texel) == 0:
            continue
        radiance = display_to_radiance(display, config.response)
        total += np.stack([np.bincount(texel, radiance[:, c], h * w) for c in range(3)], 1)
        count += np.bincount(texel, minlength=h * w)
        clipped += np.bincount(texel, (display >= config.clip_level).any(1).astype(np.float64), h * w)
        used += 1
    if used == 0:
        raise ValueError("no photo shows any background (all masked or transparent): the lighting cannot be estimated")
    mean = total / np.maximum(count, 1)[:, None]
    observed = count.reshape(h, w)
    filled = push_pull_fill(mean.reshape(h, w, 3), observed > 0)
    environment = Environment(filled.astype(np.float32), name=ENVIRONMENT_NAME)
    share = (clipped / np.maximum(count, 1)).reshape(h, w)
    return CaptureLighting(environment, observed, share, used, config, support_plane is not None)


def proxy_radius_of(cameras: dict, config: CaptureLightingConfig) -> float:
    """The proxy sphere's radius: `config.proxy_radius` x the cameras' median distance from the object."""
    return config.proxy_radius * float(np.median([np.linalg.norm(c.center) for c in cameras.values()]))


def background_samples(image: np.ndarray, mask: np.ndarray, camera, config: CaptureLightingConfig, radius: float,
                       support_plane: tuple[np.ndarray, float] | None) -> tuple[np.ndarray, np.ndarray]:
    """One photo's background, as the panorama sees it: for a regular subsample of its pixels outside
    the (grown) mask, the panorama texel (row-major index into width / 2 x width) its ray lands on
    through the proxy, and its display value (K, 3) in [0, 1]."""
    rgb, background = _background_pixels(image, mask, config)
    if not background.any():
        return np.zeros(0, np.int64), np.zeros((0, 3))
    h, w = config.width // 2, config.width
    ys, xs = np.nonzero(background)
    step = max(1, int(np.ceil(len(ys) / config.pixels_per_photo)))
    ys, xs = ys[::step], xs[::step]
    display = rgb[ys, xs].astype(np.float64) / 255.0
    origins, directions = camera.rays_at(np.stack([xs + 0.5, ys + 0.5], -1))
    landing = origins + directions * _distance_to_proxy(origins, directions, radius, support_plane)[:, None]
    u, v = direction_to_equirect_uv(landing)
    texel = np.minimum((v * h).astype(np.int64), h - 1) * w + np.minimum((u * w).astype(np.int64), w - 1)
    return texel, display


def _background_pixels(image: np.ndarray, mask: np.ndarray, config: CaptureLightingConfig) -> tuple[np.ndarray, np.ndarray]:
    rgb = image[:, :, :3]
    grown = cv2.dilate((mask > 127).astype(np.uint8), np.ones((2 * config.mask_margin_px + 1,) * 2, np.uint8)) > 0
    background = ~grown
    if image.shape[2] == 4:  # transparent pixels saw nothing (a cut-out render or a pre-masked photo)
        background &= image[:, :, 3] == 255
    return rgb, background


def _distance_to_proxy(origins: np.ndarray, directions: np.ndarray, radius: float,
                       plane: tuple[np.ndarray, float] | None) -> np.ndarray:
    """Distance along each ray to the support plane, where it meets it first from the cameras' side,
    else to where it leaves the proxy sphere."""
    distance = _distance_to_sphere(origins, directions, radius)
    if plane is None:
        return distance
    normal, offset = np.asarray(plane[0], np.float64), float(plane[1])
    height = origins @ normal - offset  # > 0: the camera is on the plane's front side
    toward = directions @ normal  # < 0: the ray goes toward the plane
    meets = (height > 0.0) & (toward < -1e-9)
    to_plane = np.where(meets, height / np.maximum(-toward, 1e-12), np.inf)
    return np.minimum(distance, to_plane)


def _distance_to_sphere(origins: np.ndarray, directions: np.ndarray, radius: float) -> np.ndarray:
    """Distance along each ray (from inside the sphere) to where it leaves it."""
    b = np.sum(origins * directions, axis=1)
    c = np.sum(origins * origins, axis=1) - radius * radius
    return -b + np.sqrt(np.maximum(b * b - c, 0.0))


def push_pull_fill(values: np.ndarray, known: np.ndarray) -> np.ndarray:
    """Fill unknown texels of an equirectangular (H, W, C) image smoothly from the known ones.

    Pull: average known texels into ever coarser levels (wrapping in longitude); push: each unknown
    texel takes the next coarser level's value, upsampled bilinearly, so holes fill from their
    surroundings at the scale of the hole. Known texels are kept as they are.
    """
    if known.all():
        return values.copy()
    if not known.any():
        raise ValueError("nothing to fill from")
    levels = [(values * known[..., None], known.astype(np.float64))]
    while min(levels[-1][1].shape) > 2:
        v, k = levels[-1]
        hh, ww = v.shape[0] // 2 * 2, v.shape[1] // 2 * 2
        v, k = v[:hh, :ww], k[:hh, :ww]
        sv = v.reshape(hh // 2, 2, ww // 2, 2, -1).sum(axis=(1, 3))
        sk = k.reshape(hh // 2, 2, ww // 2, 2).sum(axis=(1, 3))
        levels.append((sv, sk))
    # Coarsest level: the mean of what is known fills whatever is still empty.
    v, k = levels[-1]
    grand = levels[0][0].reshape(-1, values.shape[-1]).sum(0) / levels[0][1].sum()
    estimate = np.where(k[..., None] > 0, v / np.maximum(k, 1e-12)[..., None], grand)
    for v, k in reversed(levels[:-1]):
        up = _upsample_wrapped(estimate, v.shape[:2])
        mean = v / np.maximum(k, 1e-12)[..., None]
        weight = np.clip(k, 0.0, 1.0)[..., None]  # a level's texel is trusted once it averages one known texel
        estimate = weight * mean + (1.0 - weight) * up
    return np.where(known[..., None], values, estimate)


def _upsample_wrapped(image: np.ndarray, shape: tuple[int, int]) -> np.ndarray:
    pad = np.concatenate([image[:, -1:], image, image[:, :1]], axis=1)
    big = cv2.resize(pad.astype(np.float32), ((image.shape[1] + 2) * 2, image.shape[0] * 2), interpolation=cv2.INTER_LINEAR)
    big = big[:, 2:-2]
    out = np.zeros(shape + (image.shape[-1],), np.float64)
    hh, ww = min(shape[0], big.shape[0]), min(shape[1], big.shape[1])
    out[:hh, :ww] = big[:hh, :ww].reshape(hh, ww, -1)
    if hh < shape[0]:
        out[hh:, :ww] = out[hh - 1:hh, :ww]
    if ww < shape[1]:
        out[:, ww:] = out[:, ww - 1:ww]
    return out


def load_capture_lighting(capture_root: str | Path) -> CaptureLighting | None:
    """The capture's saved estimate (None when it has none)."""
    from lirm.engine.assets.environment_files import load_environment_file

    folder = Path(capture_root) / LIGHTING_FOLDER
    if not (folder / PANORAMA_FILE).is_file() or not (folder / OBSERVED_FILE).is_file():
        return None
    environment = load_environment_file(folder / PANORAMA_FILE)
    environment.name = ENVIRONMENT_NAME
    with np.load(folder / OBSERVED_FILE) as data:
        observed, clipped = data["observed"].astype(np.float64), data["clipped"].astype(np.float64)
    info = load_capture_lighting_info(capture_root) or {}
    config = CaptureLightingConfig(**info["config"]) if "config" in info else CaptureLightingConfig()
    return CaptureLighting(environment, observed, clipped, int(info.get("photos_used", 0)), config,
                           info.get("proxy") == "support plane and sphere")


def last_lighting_stage_entry(history: list) -> dict | None:
    """The capture history's last word from the lighting stage (what it estimated, or why nothing),
    None before the stage has run."""
    said = [entry for entry in history if isinstance(entry, dict) and entry.get("action") == "lighting"]
    return said[-1] if said else None


def missing_lighting_reason(capture_root: str | Path) -> str:
    """Why a capture has no estimate: what its lighting stage said, or that the stage has not run yet
    (and the command that runs it)."""
    try:
        history = json.loads((Path(capture_root) / "capture.json").read_text()).get("history", [])
    except (OSError, ValueError, AttributeError):
        return "its capture.json cannot be read"
    entry = last_lighting_stage_entry(history)
    if entry is None:
        return f"not estimated yet: `lirm capture --resume {capture_root}` estimates it from the photos' backgrounds"
    return str(entry.get("reason") or "not estimated")


def load_capture_lighting_info(capture_root: str | Path) -> dict | None:
    path = Path(capture_root) / LIGHTING_FOLDER / INFO_FILE
    return json.loads(path.read_text()) if path.is_file() else None


def camera_response_of(environment: str | Path) -> str:
    """The tone curve (camera_response.RESPONSES) a capture's lighting estimate was read through, when
    `environment` is a capture folder or its `LIGHTING_FOLDER/PANORAMA_FILE`; "aces" for anything else
    (a built-in environment, an HDRI)."""
    path = Path(environment)
    if path.is_dir():
        path = path / LIGHTING_FOLDER / PANORAMA_FILE
    if path.name != PANORAMA_FILE:
        return "aces"
    try:
        response = str(json.loads((path.parent / INFO_FILE).read_text())["config"]["response"])
    except (OSError, ValueError, KeyError, TypeError):
        return "aces"
    return response if response in RESPONSES else "aces"
