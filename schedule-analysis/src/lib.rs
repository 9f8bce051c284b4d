//! Worst-case response-time analysis of the AMiRo board tasks and the CAN bus, end to end.
