"""Scene builders, each named for what it builds:

    procedural   procedural test meshes (a fusiform muscle, an arm, a neck: points and tets)
    shapes       smooth closed surfaces (capsules, spindles) for authoring
    scenes       built-in scenes from the procedural meshes (emu.scenes.fusiform, ...)
    anatomy      built-in anatomy authored from shapes (the arm, upper limb, leg, neck)
    author       authoring from surfaces: closed part surfaces to a labelled tet mesh and scene
    datasets     the research datasets (the authors' meshes), fetched by hash
    arm26        OpenSim's arm26 bones with authored muscles, fetched by hash
"""
