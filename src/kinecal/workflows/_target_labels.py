"""The set and marker labels of compensation targets mapped onto a model's."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from kinecal.errors import DataError


def map_labels(
    labels: Sequence[str],
    index: np.ndarray,
    own: tuple[str, ...],
    path: str,
    what: str,
) -> np.ndarray:
    """Map the file's set/marker labels onto the model's, as ``kinecal evaluate`` does:
    a model of one frame takes the targets of one label (a marker only its own name);
    otherwise every label must be the model's."""
    from kinecal.measurement._calibrated import label_list

    used = [labels[i] for i in np.unique(index)]
    if len(own) == 1:
        named = [lab for lab in used if lab and own[0] and lab != own[0]]
        if len(used) > 1 or (what == "marker" and named):
            why = (
                "each marker is its own point on the tool"
                if what == "marker"
                else "each set is its own user frame"
            )
            raise DataError(
                f"{path}: column '{what}': {what}s {label_list(used, what)}, but the "
                f"model has one {what}"
                + (f" ({own[0]!r})" if own[0] else "")
                + f": {why}; expected targets of that one {what}."
            )
        return np.zeros(index.shape[0], np.intp)
    missing = [lab for lab in used if lab not in own]
    if missing and not missing[0]:
        raise DataError(
            f"{path}: no '{what}' column, but the model has {what}s "
            f"{label_list(own, what)}; expected a '{what}' column naming them."
        )
    if missing:
        raise DataError(
            f"{path}: column '{what}': {what} {missing[0]!r} is not in the model; "
            f"expected one of {label_list(own, what)}."
        )
    return np.array([own.index(lab) for lab in labels], np.intp)[index]
