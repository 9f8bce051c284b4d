//! The bus report of a robot run: observed response per message beside the analysis.
