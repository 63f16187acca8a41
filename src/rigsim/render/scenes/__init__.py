"""Per-rig Mitsuba scenes built from the same Rig (and rigsim.truth.Realization) as the truth.

- :mod:`.meshes`        trimesh-built meshes written as PLY (cube mirror, …)
- :mod:`.sun_sensor`    sun simulator seen by the distorted sun sensor at a turntable pose
- :mod:`.diaphragm`     seed 000: beam → hole → cube face → diffuse screen, seen by the aiming camera (ptracer)
- :mod:`.autocollimator` seed 001: autocollimator beam → cube face / plane mirror → its detector
- :mod:`.export`        Mitsuba XML export of a scene dict (``rigsim scene export``)

Scenes are in millimetres with the origin near the critical optical surface.
"""
