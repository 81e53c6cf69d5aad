"""Files at the edges: measurement CSVs, targets, model.yaml, JSON; units via kinecal.units.

Each name loads its module on first use (:mod:`kinecal._lazy`).
"""

from typing import TYPE_CHECKING

from kinecal import _lazy

if TYPE_CHECKING:
    from kinecal._outputs import (
        OutputTransaction,
        begin_transaction,
        current_transaction,
        end_transaction,
        new_dir_mode,
        new_file_mode,
        output_transaction,
    )
    from kinecal.io._checks import DataWarning, check_data_for_model, data_diagnostics
    from kinecal.io._compensation_csv import (
        CompensationTargets,
        read_compensation_targets,
    )
    from kinecal.io._csv import (
        Table,
        Targets,
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
        atomic_write_files,
        atomic_write_text,
        file_sha256,
        json_text,
        prepare_output_dir,
        write_json,
    )
    from kinecal.io._model_file import (
        FORMAT_VERSION,
        load_model,
        model_to_dict,
        save_model,
    )
    from kinecal.io._parameters import parameter_records
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
    "OutputTransaction",
    "Program",
    "ProgramPoint",
    "Table",
    "Targets",
    "atomic_write_bytes",
    "atomic_write_files",
    "atomic_write_text",
    "begin_transaction",
    "check_data_for_model",
    "csv_text",
    "current_transaction",
    "data_diagnostics",
    "detect_program_format",
    "end_transaction",
    "extrapolation",
    "file_sha256",
    "image_files",
    "joint_column_names",
    "json_text",
    "load_model",
    "load_sensor",
    "measurements_to_csv",
    "model_to_dict",
    "new_dir_mode",
    "new_file_mode",
    "output_transaction",
    "parameter_records",
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

__getattr__, __dir__ = _lazy.exports(
    __name__,
    {
        "kinecal._outputs": (
            "OutputTransaction",
            "begin_transaction",
            "current_transaction",
            "end_transaction",
            "new_dir_mode",
            "new_file_mode",
            "output_transaction",
        ),
        "_checks": (
            "DataWarning",
            "check_data_for_model",
            "extrapolation",
            "data_diagnostics",
        ),
        "_compensation_csv": ("CompensationTargets", "read_compensation_targets"),
        "_csv": (
            "Table",
            "Targets",
            "read_data",
            "read_measurements",
            "read_table",
            "read_targets",
        ),
        "_csv_format": (
            "Column",
            "csv_text",
            "table_csv",
        ),
        "_csv_write": (
            "joint_column_names",
            "measurements_to_csv",
            "write_measurements",
            "write_targets",
        ),
        "_files": (
            "atomic_write_bytes",
            "atomic_write_files",
            "atomic_write_text",
            "file_sha256",
            "json_text",
            "prepare_output_dir",
            "write_json",
        ),
        "_model_file": (
            "FORMAT_VERSION",
            "load_model",
            "model_to_dict",
            "save_model",
        ),
        "_parameters": ("parameter_records",),
        "_programs": (
            "PROGRAM_FORMATS",
            "Program",
            "ProgramPoint",
            "detect_program_format",
            "program_bytes",
            "program_joints",
            "read_program",
            "write_program",
            "written_joints",
        ),
        "_sensor_files": (
            "image_files",
            "load_sensor",
            "read_cloud",
            "read_image",
            "save_sensor",
            "write_cloud",
            "write_image",
            "write_stripes",
        ),
        "_urdf_export": (
            "robot_yaml_text",
            "urdf_text",
        ),
    },
)
