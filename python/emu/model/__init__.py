"""The scene and what it is made of: parts and materials, joints, contact,
the lowering of a scene to the C++ model, and bone motion measured on positions."""
