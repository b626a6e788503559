//! `rackd db copy` (see src/store/copy.rs).
