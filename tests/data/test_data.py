"""The splitcam.data package: its names are imported on first use."""

from __future__ import annotations

import pytest
from conftest import fresh_modules

from splitcam.data import registry, testsets


@pytest.mark.integration
def test_data_package_imports_its_names_on_first_use() -> None:
    import splitcam.data as data
    from splitcam.data import images, patches, raw

    assert "torch" not in fresh_modules("import splitcam.data")
    assert data.read_image is images.read_image
    assert data.write_raw is raw.write_raw
    assert data.ImageCache is patches.ImageCache
    assert data.load_images is testsets.load_images
    assert set(data.__all__) <= set(dir(data))
    assert {"registry", "download", "testsets", "images", "raw"} <= set(dir(data))
    assert data.registry is registry
    with pytest.raises(AttributeError, match="no attribute 'nothing'"):
        data.nothing  # noqa: B018
