//! The AMiRo robot's CAN protocol: the single source of truth for identifiers, topics, commands and payloads.
#![cfg_attr(not(test), no_std)]
#![deny(missing_docs)]
