//! File formats for chiaro: the TOML scene format, OBJ+MTL, glTF 2.0, and PNG/EXR/HDR/PPM output.
