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
    atomic_write_bytes,
    atomic_write_text,
    file_sha256,
    prepare_output_dir,
    write_json,
)
from kinecal.io._model_file import FORMAT_VERSION, load_model, model_to_dict, save_model
from kinecal.io._sensor_files import (
    image_files,
    load_sensor,
    read_cloud,
    read_image,
    save_sensor,
    write_cloud,
    write_image,
    write_stripes,
)

__all__ = [
    "FORMAT_VERSION",
    "CompensationTargets",
    "Table",
    "Targets",
    "atomic_write_bytes",
    "atomic_write_text",
    "file_sha256",
    "image_files",
    "joint_column_names",
    "load_model",
    "load_sensor",
    "measurements_to_csv",
    "model_to_dict",
    "prepare_output_dir",
    "read_cloud",
    "read_compensation_targets",
    "read_image",
    "read_measurements",
    "read_table",
    "read_targets",
    "save_model",
    "save_sensor",
    "write_cloud",
    "write_image",
    "write_json",
    "write_measurements",
    "write_stripes",
    "write_targets",
]
