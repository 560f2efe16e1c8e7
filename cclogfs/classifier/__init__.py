"""Anomaly classifier front end: odometry features, one-class SVM, logging windows.

Knows nothing of storage: the pipeline and the CLI store what `SmartLogger` emits.
"""

from .api import Detector, SmartLogger, collect, load_dataset, parse_labels, train
from .evaluate import event_table, format_event_table, format_message_table, message_table, window_spans
from .features import DefaultFeatures, OdomArrays, PaperFeatures, make_features, parse_odometry
from .model import OneClassModel
from .summary import SUMMARY_TOPIC, SummaryBuilder
from .windows import PendingWindow, WindowBuilder

__all__ = [
    "SUMMARY_TOPIC",
    "DefaultFeatures",
    "Detector",
    "PendingWindow",
    "OdomArrays",
    "OneClassModel",
    "PaperFeatures",
    "SmartLogger",
    "SummaryBuilder",
    "WindowBuilder",
    "collect",
    "event_table",
    "format_event_table",
    "format_message_table",
    "load_dataset",
    "make_features",
    "message_table",
    "parse_labels",
    "parse_odometry",
    "train",
    "window_spans",
]
