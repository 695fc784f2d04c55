"""Real motion capture in: BVH files with their recordings, onto the course's skeleton.

* :mod:`gesturelib.mocap.bvh_reader`: any BVH file, its hierarchy and its joints in the world;
* :mod:`gesturelib.mocap.rigs`: which joint of a common rig is which of our keypoints;
* :mod:`gesturelib.mocap.retarget`: a BVH take as our 9 keypoints at 25 fps, facing +z;
* :mod:`gesturelib.mocap.dataset`: a folder of takes and recordings imported as a dataset that
  ``train --data`` and ``evaluate --data`` take (``python -m gesturelib import-bvh``).
"""
