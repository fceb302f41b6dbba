// The source of fmv3d_pch (cmake/Pch.cmake): the target exists to build the precompiled header that every other
// target reuses; it compiles nothing of its own.
