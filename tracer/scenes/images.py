"""Texture images on disk: PNG and JPEG in, PNG out (through Pillow).

Scenes hold textures as (height, width, 4) uint8 RGBA arrays, row 0 at the
top (:meth:`tracer.scenes.model.SceneBuilder.texture`). :func:`read_image` gives
any PNG or JPEG in that form: grey, palette and RGB images get alpha 255,
16-bit grey keeps its high byte. :func:`write_png` writes such an array
losslessly, so reading it back gives the same texels.
"""
from __future__ import annotations

import io
from pathlib import Path

import numpy as np

from rtcommon.files import regular_file, write_bytes_atomic

__all__ = ["read_image", "png_bytes", "write_png", "IMAGE_FORMATS"]

#: the formats :func:`read_image` accepts (Pillow's names)
IMAGE_FORMATS = ("PNG", "JPEG")


def read_image(path) -> np.ndarray:
    """A PNG or JPEG file as an RGBA image.

    Parameters
    ----------
    path : str or os.PathLike

    Returns
    -------
    ndarray of uint8, shape (height, width, 4)
        Row 0 is the image's top row.

    Raises
    ------
    FileNotFoundError
        No such file.
    IsADirectoryError
        ``path`` is a folder.
    ValueError
        Not a regular file, or not a PNG or JPEG that Pillow can decode
        (the message names the file and Pillow's reason).
    """
    from PIL import Image, UnidentifiedImageError

    path = regular_file(path, "an image file")
    try:
        with Image.open(path, formats=IMAGE_FORMATS) as image:
            image.load()
            if image.mode in ("I", "I;16", "I;16B", "I;16L", "I;16N"):
                # 16-bit grey: Pillow's RGBA conversion would clip it to white
                grey = (np.clip(np.asarray(image, dtype=np.int64), 0, 65535) >> 8).astype(np.uint8)
                rgba = np.repeat(grey[:, :, None], 4, axis=2)
                rgba[:, :, 3] = 255
            else:
                rgba = np.asarray(image.convert("RGBA"), dtype=np.uint8)
    except UnidentifiedImageError:
        raise ValueError(f"not a PNG or JPEG image: {str(path)!r}") from None
    except (OSError, SyntaxError, ValueError) as error:  # truncated or corrupt data
        raise ValueError(f"unreadable image {str(path)!r}: {error}") from None
    return np.ascontiguousarray(rgba)


def _rgba(image) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 4 or min(image.shape[:2]) < 1:
        raise ValueError(f"an image must be uint8 of shape (height, width, 4), got {image.dtype} {image.shape}")
    return np.ascontiguousarray(image)


def png_bytes(image) -> bytes:
    """The PNG file of an RGBA image (height, width, 4) uint8, row 0 at the top."""
    from PIL import Image

    buffer = io.BytesIO()
    Image.fromarray(_rgba(image)).save(buffer, format="PNG")
    return buffer.getvalue()


def write_png(image, path) -> Path:
    """Write an RGBA image (height, width, 4) uint8 as a PNG file, atomically.

    Returns
    -------
    Path
        The written path.
    """
    path = Path(path)
    write_bytes_atomic(path, png_bytes(image))
    return path
