"""Files at the edges: measurement CSVs, targets, model.yaml, JSON; units via kinecal.units."""

from kinecal.io._checks import DataWarning, check_data_for_model, data_diagnostics
from kinecal.io._csv import (
    CompensationTargets,
    Table,
    Targets,
    read_compensation_targets,
    read_data,
    read_measurements,
    read_table,
    read_targets,
)
from kinecal.io._csv_format import Column, csv_text, table_csv
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
from kinecal.io._programs import (
    PROGRAM_FORMATS,
    Program,
    ProgramPoint,
    detect_program_format,
    program_bytes,
    program_joints,
    read_program,
    write_program,
    written_joints,
)
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
from kinecal.io._urdf_export import robot_yaml_text, urdf_text

__all__ = [
    "FORMAT_VERSION",
    "PROGRAM_FORMATS",
    "Column",
    "CompensationTargets",
    "DataWarning",
    "Program",
    "ProgramPoint",
    "Table",
    "Targets",
    "atomic_write_bytes",
    "atomic_write_text",
    "check_data_for_model",
    "csv_text",
    "data_diagnostics",
    "detect_program_format",
    "file_sha256",
    "image_files",
    "joint_column_names",
    "load_model",
    "load_sensor",
    "measurements_to_csv",
    "model_to_dict",
    "prepare_output_dir",
    "program_bytes",
    "program_joints",
    "read_cloud",
    "read_compensation_targets",
    "read_data",
    "read_image",
    "read_measurements",
    "read_program",
    "read_table",
    "read_targets",
    "robot_yaml_text",
    "save_model",
    "save_sensor",
    "table_csv",
    "urdf_text",
    "write_cloud",
    "write_image",
    "write_json",
    "write_measurements",
    "write_program",
    "write_stripes",
    "write_targets",
    "written_joints",
]
