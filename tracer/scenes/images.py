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
from tracer.rendering.texture import MAX_TEXELS
from rtcommon.validate import InputError

__all__ = ["read_image", "image_size", "png_bytes", "write_png", "IMAGE_FORMATS", "MAX_IMAGE_TEXELS"]

#: the formats :func:`read_image` accepts (Pillow's names)
IMAGE_FORMATS = ("PNG", "JPEG")
#: The most texels a texture image may hold: as many as a trace can name
#: (2^27, 512 MiB of RGBA). A larger image is refused from its header,
#: before its pixels are decoded.
MAX_IMAGE_TEXELS = MAX_TEXELS


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
        Not a regular file, not a PNG or JPEG that Pillow can decode (the
        message names the file and Pillow's reason), or larger than
        :data:`MAX_IMAGE_TEXELS` (checked before the pixels are decoded).
    """
    path = regular_file(path, "an image file")
    with _opened(path) as image:
        _check_size(path, image.size)
        try:
            image.load()
            if image.mode in ("I", "I;16", "I;16B", "I;16L", "I;16N"):
                # 16-bit grey: Pillow's RGBA conversion would clip it to white
                grey = (np.clip(np.asarray(image, dtype=np.int64), 0, 65535) >> 8).astype(np.uint8)
                rgba = np.repeat(grey[:, :, None], 4, axis=2)
                rgba[:, :, 3] = 255
            else:
                rgba = np.asarray(image.convert("RGBA"), dtype=np.uint8)
        except (OSError, SyntaxError, ValueError) as error:  # truncated or corrupt data
            raise InputError(f"unreadable image {str(path)!r}: {error}") from None
    return np.ascontiguousarray(rgba)


def image_size(path) -> tuple[int, int]:
    """Width and height of a PNG or JPEG file, from its header (no pixel is decoded).

    Raises
    ------
    FileNotFoundError, IsADirectoryError, ValueError
        As :func:`read_image`: no such file, a folder, not a readable PNG or
        JPEG, or more than :data:`MAX_IMAGE_TEXELS` texels.
    """
    path = regular_file(path, "an image file")
    with _opened(path) as image:
        return _check_size(path, image.size)


def _opened(path):
    """Pillow's lazy image of ``path`` (header read), whatever its size: :func:`_check_size` judges that.

    Pillow refuses an image above twice its own pixel limit as a possible
    decompression bomb before a caller sees its size; such an image is opened
    with its format's own class, which reads the header alone, so that the
    refusal names the size and our limit.

    Raises
    ------
    ValueError
        Not a PNG or JPEG, or a header Pillow cannot read (naming the file).
    """
    import warnings

    from PIL import Image, JpegImagePlugin, PngImagePlugin, UnidentifiedImageError

    try:
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", Image.DecompressionBombWarning)
            return Image.open(path, formats=IMAGE_FORMATS)
    except Image.DecompressionBombError:
        pass
    except UnidentifiedImageError:
        raise InputError(f"not a PNG or JPEG image: {str(path)!r}") from None
    except (OSError, SyntaxError, ValueError) as error:
        raise InputError(f"unreadable image {str(path)!r}: {error}") from None
    for image_class in (PngImagePlugin.PngImageFile, JpegImagePlugin.JpegImageFile):
        try:
            return image_class(path)
        except (OSError, SyntaxError):
            continue
    raise InputError(f"not a PNG or JPEG image: {str(path)!r}")


def _check_size(path, size) -> tuple[int, int]:
    width, height = (int(v) for v in size)
    if width * height > MAX_IMAGE_TEXELS:
        raise InputError(f"image {str(path)!r} is {width} x {height} ({width * height:,} texels); a texture may "
                         f"hold at most {MAX_IMAGE_TEXELS:,} texels")
    return width, height


def _rgba(image) -> np.ndarray:
    image = np.asarray(image)
    if image.dtype != np.uint8 or image.ndim != 3 or image.shape[2] != 4 or min(image.shape[:2]) < 1:
        raise InputError(f"an image must be uint8 of shape (height, width, 4), got {image.dtype} {image.shape}")
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
