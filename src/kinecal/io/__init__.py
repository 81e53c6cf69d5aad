"""Files at the edges: measurement CSVs, targets, model.yaml, JSON; units via kinecal.units."""

from kinecal.io._csv import (
    CompensationTargets,
    Table,
    Targets,
    read_compensation_targets,
    read_measurements,
    read_table,
    read_targets,
)
from kinecal.io._csv_write import (
    joint_column_names,
    measurements_to_csv,
    write_measurements,
    write_targets,
)
from kinecal.io._files import (
    atomic_write_text,
    file_sha256,
    prepare_output_dir,
    write_json,
)
from kinecal.io._model_file import FORMAT_VERSION, load_model, model_to_dict, save_model

__all__ = [
    "FORMAT_VERSION",
    "CompensationTargets",
    "Table",
    "Targets",
    "atomic_write_text",
    "file_sha256",
    "joint_column_names",
    "load_model",
    "measurements_to_csv",
    "model_to_dict",
    "prepare_output_dir",
    "read_compensation_targets",
    "read_measurements",
    "read_table",
    "read_targets",
    "save_model",
    "write_json",
    "write_measurements",
    "write_targets",
]
