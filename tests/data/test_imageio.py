"""splitcam.data.imageio gathers the names of image and raw files."""

from __future__ import annotations


def test_imageio_gathers_the_image_and_raw_names() -> None:
    from splitcam.data import imageio, images
    from splitcam.data import raw as raw_files

    for name in imageio.__all__:
        module = images if name in images.__all__ else raw_files
        assert getattr(imageio, name) is getattr(module, name), name
    assert set(imageio.__all__) == set(images.__all__) | set(raw_files.__all__)
