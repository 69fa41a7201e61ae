"""Writing EXT_meshopt_compression GLBs for tests, with meshoptimizer's own encoder (PyPI `meshopt`),
the layout gltfpack writes: the compressed bytes in the BIN chunk, a fallback buffer holding nothing."""
from __future__ import annotations

from pathlib import Path

import numpy as np

from scenefit.core.gltf_meshopt import EXTENSION, read_gltf, write_glb

_COMPONENT_BYTES = {5120: 1, 5121: 1, 5122: 2, 5123: 2, 5125: 4, 5126: 4}
_TYPE_COUNT = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT4": 16}
ELEMENT_ARRAY_BUFFER = 34963


def meshopt_encoded(source: Path, out: Path) -> Path:
    """`source` (a plain GLB) with every vertex and index bufferView compressed; images stay plain."""
    import meshopt

    document, chunk = read_gltf(source)
    element = {}  # bufferView -> the size of one element of the accessors reading it
    for accessor in document["accessors"]:
        element[accessor["bufferView"]] = _COMPONENT_BYTES[accessor["componentType"]] * _TYPE_COUNT[accessor["type"]]
    blob, fallback = bytearray(), 0
    for index, view in enumerate(document["bufferViews"]):
        data = chunk[view.get("byteOffset", 0):][:view["byteLength"]]
        blob.extend(b"\0" * (-len(blob) % 4))
        if index not in element:  # an image
            view.update(buffer=0, byteOffset=len(blob))
            blob.extend(data)
            continue
        stride = view.get("byteStride", element[index])
        count = view["byteLength"] // stride
        if view.get("target") == ELEMENT_ARRAY_BUFFER:
            mode = "TRIANGLES"
            packed = meshopt.encode_gltf_buffer(np.frombuffer(data, f"<u{stride}").astype(np.uint32), mode)
        else:
            mode = "ATTRIBUTES"
            packed = meshopt.encode_gltf_buffer(np.frombuffer(data, np.uint8).reshape(count, stride), mode)
        view["extensions"] = {EXTENSION: {"buffer": 0, "byteOffset": len(blob), "byteLength": len(packed),
                                          "byteStride": stride, "count": count, "mode": mode}}
        fallback += -fallback % 4
        view.update(buffer=1, byteOffset=fallback)
        fallback += view["byteLength"]
        blob.extend(packed)
    document["buffers"] = [{"byteLength": len(blob)},
                           {"byteLength": fallback, "extensions": {EXTENSION: {"fallback": True}}}]
    for key in ("extensionsUsed", "extensionsRequired"):
        document[key] = sorted(set(document.get(key, [])) | {EXTENSION})
    write_glb(out, document, bytes(blob))
    return out
