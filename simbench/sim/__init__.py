"""The simulator: from a scene file and a pattern to what a real camera records.

- :mod:`~simbench.sim.scene`: scene specifications (TOML), object kinds, materials;
  :mod:`~simbench.sim.mitsuba_dict`: their Mitsuba scene dictionaries and render settings.
- :mod:`~simbench.sim.render`, :mod:`~simbench.sim.truth`: path-traced radiance and ground truth.
- :mod:`~simbench.sim.sensor`: the sensor model (camera, projector, lenses, ambient light) as one
  frozen configuration; :mod:`~simbench.sim.camera`: what the camera records from radiance;
  :mod:`~simbench.sim.photometry`: lumens to electrons, exposure, white balance;
  :mod:`~simbench.sim.projector`: what the projector emits for an 8-bit pattern;
  :mod:`~simbench.sim.spectral`: crosstalk between primaries and camera channels;
  :mod:`~simbench.sim.subsurface`: translucent materials.
- :mod:`~simbench.sim.drive`: the projector drive; :mod:`~simbench.sim.capture`: the chain for
  one capture (drive -> render -> camera); :mod:`~simbench.sim.keys`: its cache keys.
- :mod:`~simbench.sim.synthetic`: analytic captures of a plane (no Mitsuba), for tests.

The depth systems (:mod:`simbench.systems`) build their acquisitions from this package; nothing
here imports a system, an experiment or the command line.
"""
