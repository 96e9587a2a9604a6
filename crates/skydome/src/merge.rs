//! merge (in progress).
