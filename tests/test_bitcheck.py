"""tests/bitcheck.py, the before/after tool for changes that must not change any image: a record
compares equal to itself, and one changed bit is caught."""
import numpy as np

import bitcheck


def test_bitcheck_catches_one_changed_bit(tmp_path):
    only = ["smoke_sphere"]
    bitcheck.record(tmp_path, only=only)
    records = sorted(tmp_path.glob("*.npz"))
    assert [p.stem for p in records] == ["smoke_sphere-all-features", "smoke_sphere-bsdf-only", "smoke_sphere-mis",
                                         "smoke_sphere-nee-only"]
    assert bitcheck.compare(tmp_path, only=only) == []
    with np.load(records[0]) as z:
        arrays = dict(z)
    image = arrays["image"].copy()
    image.view(np.uint32)[3, 4, 1] ^= 1                     # the last bit of one channel of one pixel
    np.savez(records[0], **dict(arrays, image=image))
    assert bitcheck.compare(tmp_path, only=only) == [f"{records[0].stem}: image differs (max abs difference "
                                                     f"{abs(float(image[3, 4, 1]) - float(arrays['image'][3, 4, 1]))})"]
