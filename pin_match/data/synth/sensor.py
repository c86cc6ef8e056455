"""A camera's sensor and processing between the rendered light and the stored bytes: what makes a render a photo.

A renderer gives every episode exact, noise-free colours, so a product is the same RGB in every
frame and in its reference views; a real camera does not. Per camera (an episode's, or each
object's reference camera: PIN's references are renders under other light than the house) a
``Sensor`` draws a white balance, an exposure, a tone curve (gamma) and a saturation; per frame
it blurs (focus and motion), adds shot noise (grows with the signal) and read noise (does not),
and stores the picture as a JPEG at a quality of its own. Only colours change here: masks and
depth stay the renderer's exact buffers.
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

DISPLAY_GAMMA = 2.2  # the renderer's colours are display values; light adds up in linear values
_TO_LINEAR = ((np.arange(256) / 255.0) ** DISPLAY_GAMMA).astype(np.float32)
_LUMA = np.array([0.299, 0.587, 0.114], np.float32)


@dataclass(frozen=True)
class Sensor:
    """One camera's settings: drawn once per camera, applied to each of its pictures with that picture's own noise."""

    white_balance: tuple[float, float, float]  # gain per channel (R, G, B) on linear light
    exposure: float  # gain on linear light
    gamma: float  # the tone curve's exponent relative to the display's: above 1 darker mid-tones, below 1 lighter
    saturation: float  # 1 keeps the colours, 0 makes grey
    shot_noise: float  # variance of the noise per unit of linear signal
    read_noise: float  # standard deviation of the signal-independent noise (linear units)
    blur: tuple[float, float]  # each picture's Gaussian blur sigma (pixels) is drawn in this range
    jpeg: tuple[int, int] = (70, 92)  # each picture's JPEG quality is drawn in this range (``encode``)

    def develop(self, image: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """The RGB uint8 picture this camera makes of a rendered RGB uint8 ``image`` (its noise from ``rng``), before
        any compression."""
        light = _TO_LINEAR[image] * (np.float32(self.exposure) * np.asarray(self.white_balance, np.float32))
        sigma = float(rng.uniform(*self.blur))
        if sigma > 0:
            light = cv2.GaussianBlur(light, (0, 0), sigma)
        noise_sd = np.sqrt(self.shot_noise * np.clip(light, 0.0, None) + self.read_noise ** 2)
        light = light + noise_sd * rng.standard_normal(light.shape, dtype=np.float32)
        tone = np.clip(light, 0.0, 1.0) ** np.float32(self.gamma / DISPLAY_GAMMA)
        grey = (tone @ _LUMA)[..., None]
        return np.clip(np.round((grey + self.saturation * (tone - grey)) * 255.0), 0, 255).astype(np.uint8)

    def encode(self, image: np.ndarray, rng: np.random.Generator) -> bytes:
        """The JPEG file the camera stores of a developed ``image``, at a quality drawn from ``jpeg``: the frame's
        file as it is, so a frame is compressed once, as a phone's photo is."""
        quality = int(rng.integers(self.jpeg[0], self.jpeg[1] + 1))
        ok, data = cv2.imencode(".jpg", cv2.cvtColor(image, cv2.COLOR_RGB2BGR), [cv2.IMWRITE_JPEG_QUALITY, quality])
        if not ok:
            raise RuntimeError(f"OpenCV could not encode a {image.shape} image as JPEG")
        return data.tobytes()


def _white_balance(rng: np.random.Generator, spread: float) -> tuple[float, float, float]:
    """Red and blue gains relative to green, each within a factor exp(+-spread): a guess at the light's colour."""
    red, blue = np.exp(rng.uniform(-spread, spread, 2))
    return float(red), 1.0, float(blue)


def house_camera(rng: np.random.Generator) -> Sensor:
    """The agent's camera in one episode: a phone-like sensor under the house's light, a JPEG per frame."""
    return Sensor(white_balance=_white_balance(rng, 0.12), exposure=float(np.exp(rng.uniform(-0.3, 0.3))),
                  gamma=float(rng.uniform(0.85, 1.15)), saturation=float(rng.uniform(0.8, 1.2)),
                  shot_noise=float(rng.uniform(2e-4, 8e-4)), read_noise=float(rng.uniform(1e-3, 3e-3)),
                  blur=(0.3, 1.1), jpeg=(70, 92))


def reference_camera(rng: np.random.Generator) -> Sensor:
    """The camera of one object's reference views: a studio render under its own light, another white balance and
    tone, little noise, no blur (the views are stored as PNG with their alpha: never encoded as JPEG)."""
    return Sensor(white_balance=_white_balance(rng, 0.08), exposure=float(np.exp(rng.uniform(-0.2, 0.2))),
                  gamma=float(rng.uniform(0.9, 1.1)), saturation=float(rng.uniform(0.9, 1.1)),
                  shot_noise=1e-4, read_noise=5e-4, blur=(0.0, 0.0))


def develop_view(sensor: Sensor, view: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """An RGBA reference view through ``sensor``: the colours change, the alpha (the object's exact coverage) and
    the white outside the object do not."""
    rgb = sensor.develop(np.ascontiguousarray(view[..., :3]), rng)
    outside = view[..., 3] == 0
    rgb[outside] = view[..., :3][outside]
    return np.dstack([rgb, view[..., 3]])
