"""Tabletop pick-and-place in MuJoCo: "put the <object> on the <goal>" (design section 4).

Light to import; MuJoCo and trimesh load only with sim.tabletop.model, .meshes and friends.
"""
