//! Helpers shared by the end-to-end vcan tests: locating the built binaries, interface names.
