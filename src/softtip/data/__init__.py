"""Recorded and simulated trials: the dataset format, a CSV loader and trial-wise splits.

- :mod:`softtip.data.dataset`: :class:`Dataset` (one Parquet file, metadata as JSON),
  :class:`TrialWriter` (trial by trial), :func:`concat`, and the channel names
  (:func:`channel_name`, :func:`channel_names`, :func:`channel_columns`, from
  :mod:`softtip._core.channels`);
- :mod:`softtip.data.csvload`: :func:`read_csv_recording` (a column mapping and unit
  conversion for real recordings) and :func:`read_columns` (numbers from any delimited text);
- :mod:`softtip.data.splits`: calibration / validation splits that keep every trial on one
  side (:func:`split_by_trial`, :func:`kfold_by_trial`, :class:`TrialKFold`,
  :func:`leave_condition_out`), and :func:`split_by_sample`, which warns.
"""

from softtip._core.channels import channel_columns, channel_name, channel_names
from softtip.data.csvload import TIME_UNITS_IN_S, read_columns, read_csv_recording
from softtip.data.dataset import (
    FORMAT,
    SCHEMA_VERSION,
    Dataset,
    DatasetError,
    DatasetMetadata,
    TrialWriter,
    concat,
    is_dataset_file,
    subtract_trial_baseline,
)
from softtip.data.splits import (
    LeakageWarning,
    TrialKFold,
    kfold_by_trial,
    leave_condition_out,
    split_by_sample,
    split_by_trial,
)

__all__ = [
    "FORMAT",
    "SCHEMA_VERSION",
    "TIME_UNITS_IN_S",
    "Dataset",
    "DatasetError",
    "DatasetMetadata",
    "LeakageWarning",
    "TrialKFold",
    "TrialWriter",
    "channel_columns",
    "channel_name",
    "channel_names",
    "concat",
    "is_dataset_file",
    "kfold_by_trial",
    "leave_condition_out",
    "read_columns",
    "read_csv_recording",
    "split_by_sample",
    "split_by_trial",
    "subtract_trial_baseline",
]
