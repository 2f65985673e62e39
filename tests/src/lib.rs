//! End-to-end tests of fresco live in `tests/tests/`; this library is empty.
