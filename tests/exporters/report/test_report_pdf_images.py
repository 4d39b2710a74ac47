"""The PDF's embedded images: handed to WeasyPrint as bytes, the page the same as before."""

from __future__ import annotations

import base64
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from exporters.errors import ExportError
from exporters.plots.png import rgb_png
from exporters.report import html_to_pdf
from exporters.report.render import _hoist_images

pytestmark = pytest.mark.pdf


def _png(rgb: tuple[int, int, int], size: int = 40) -> bytes:
    canvas = np.zeros((size, size, 4), dtype=np.uint8)
    canvas[:, :] = (*rgb, 255)
    return rgb_png(canvas, dpi=96, software="test")


def _uri(data: bytes) -> str:
    return "data:image/png;base64," + base64.b64encode(data).decode("ascii")


def _page(images: list[bytes], text: str) -> bytes:
    tags = "".join(f'<img src="{_uri(data)}" alt="figure {k}">' for k, data in enumerate(images))
    return f"<!DOCTYPE html><html><body><p>{text}</p>{tags}</body></html>".encode()


def test_src_images_are_taken_out_and_text_that_looks_like_one_stays() -> None:
    """Only ``src="data:..."`` values are hoisted; the same words in text are left alone."""
    red, blue = _png((255, 0, 0)), _png((0, 0, 255))
    words = "data:image/png;base64,AAAA is what a figure looks like inside"
    text, images = _hoist_images(_page([red, blue], words))

    assert list(images.values()) == [("image/png", red), ("image/png", blue)]
    assert all(f'src="{url}"' in text for url in images)
    assert words in text
    assert "base64,iVBOR" not in text  # no PNG left in the HTML


def _pdf_images(pdf: bytes, folder: Path) -> list[np.ndarray]:
    """The PDF's images, decoded by poppler (an independent reader), in page order."""
    (folder / "r.pdf").write_bytes(pdf)
    subprocess.run(["pdfimages", "-png", str(folder / "r.pdf"), str(folder / "i")], check=True)
    return [np.asarray(Image.open(p).convert("RGB")) for p in sorted(folder.glob("i-*.png"))]


@pytest.mark.skipif(shutil.which("pdfimages") is None, reason="needs poppler-utils (pdfimages)")
def test_the_pdf_holds_every_image_pixel_for_pixel(tmp_path: Path) -> None:
    """Each figure reaches the PDF whole: poppler reads back the pixels that were embedded."""
    rng = np.random.default_rng(3)
    canvases = [rng.integers(0, 256, size=(30 + k, 50, 4), dtype=np.uint8) for k in range(3)]
    pngs = [rgb_png(c, dpi=96, software="test") for c in canvases]

    found = _pdf_images(html_to_pdf(_page(pngs, "three figures")), tmp_path)

    assert len(found) == len(canvases)
    for image, canvas in zip(found, canvases, strict=True):
        np.testing.assert_array_equal(image, canvas[:, :, :3])


@pytest.mark.skipif(shutil.which("pdftotext") is None, reason="needs poppler-utils (pdftotext)")
def test_the_words_of_a_page_survive_hoisting(tmp_path: Path) -> None:
    """Text shaped like a data URL is printed as written, not fetched or replaced."""
    words = "data:image/png;base64,AAAA"
    pdf = html_to_pdf(_page([_png((0, 128, 0))], words))
    (tmp_path / "r.pdf").write_bytes(pdf)
    out = subprocess.run(
        ["pdftotext", str(tmp_path / "r.pdf"), "-"], capture_output=True, text=True, check=True
    )
    assert words in out.stdout


def test_an_image_that_is_not_embedded_still_stops_the_pdf() -> None:
    """Beside hoisted figures, a file URL (not data:, not hoisted) is refused as before."""
    html = _page([_png((1, 2, 3))], "x").replace(
        b"</body>", b'<img src="file:///etc/hostname"></body>'
    )
    with pytest.raises(ExportError, match="not embedded"):
        html_to_pdf(html)


def test_a_damaged_embedded_image_is_left_out_not_fatal() -> None:
    """A data URL whose bytes are not an image is skipped by WeasyPrint, as it was before."""
    broken = _page([b"not a png at all"], "a broken figure")
    assert html_to_pdf(broken).startswith(b"%PDF")
