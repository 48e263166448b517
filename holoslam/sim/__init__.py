"""holoslam.sim: the reference household of seed 002 as a deterministic simulation that writes MCAP logs.

Entry points::

    from holoslam.sim import SimConfig, simulate_household, simulate_to_file
    run = simulate_household(SimConfig(seed=2, duration_s=60))      # in memory, pure
    summary = simulate_to_file("household.mcap", SimConfig())        # what ``holoslam simulate`` calls

Modules: ``world`` (floor plan, furniture, 35 labelled objects, ray casting, free space), ``route`` (the
teleoperated-looking tour and its true trajectory), ``sensors`` (noise models), ``render`` (camera images),
``writer`` (MCAP), ``core`` (config and run). ``building``: another world, a 350 m building of long corridors
and 300+ rooms driven for 80 minutes with a hospital robot's sparse laser (``holoslam simulate --building``).

The world (``holoslam.sim.world``): 9.5 m x 10.5 m; living room, dining room, kitchen, study, two bedrooms,
balcony; six doorways 0.95-1.2 m wide; 25 pieces of furniture; 35 objects ``O01``..``O35`` with QR labels
(payload ``HL1;<id>;<type>;g=...,m=...,s=<side mm>``, printed sides 50-150 mm, heights 0.38-2.0 m). The chair
``O22`` stands in the dining room's north-east corner behind the table, out of the arm's reach (0.9 m) from
any free space: ``reachable`` is false for it alone (computed from the free space, not declared).

Optional extras for tests (``SimConfig.wall_codes``, ``SimConfig.sizeless_labels``; both 0 by default, so
the bundled log has neither): foreign QR codes fixed to walls (``World.codes``, photographed like labels and
published on ``/tags``; the world JSON lists them under ``codes``) and labels printed without their size.

The robot: a Pioneer III-like base (radius 0.25 m, <= 0.35 m/s, <= 35 deg/s, 0.4 m/s^2) on a tour that
visits every room, stops and turns in front of every object it can approach, passes every doorway at least
twice (in and out; a long run loops the tour), and comes back through the living room and dining room
many times (loops). Default duration 500 s (the committed ``datasets/household_small.mcap``).

Camera stream (``SimConfig.camera_rate_hz`` > 0, ``holoslam simulate --camera-rate HZ``; off by default, so the
bundled log stays small): every frame at that rate for the whole drive, like a real robot's camera topic; the
head tracks a label for ``camera_dwell_s`` after each of the operator's aims and looks ahead at zoom 1 otherwise,
so most frames show no readable code; each frame is blurred by the robot's own motion over
``camera_exposure_ms`` (``holoslam.sim.stream``).

Noise models (defaults of ``SimConfig``; details in ``holoslam.sim.sensors``):

- odometer, 20 Hz: distance scale error +1.5 %, random slip 0.01 m per sqrt(m), slip events 0.05 per metre
  (one step over-reported 1.5-3x), turn scale error +2 %, heading drift 0.5 deg per metre, turn noise
  0.02 rad per sqrt(rad), heading noise while driving 0.2 deg per sqrt(m); the pose is integrated from the
  identity and its first-order covariance reported.
- digital compass, 10 Hz: white noise 1.5 deg, constant bias 2.0 deg, local magnetic disturbances of 3-6 deg
  fading to zero 1 m from the fridge, TV, air conditioner, washing machine and microwave.
- laser (SICK LMS-200 like), 5 Hz: 181 beams, -90..+90 deg in 1 deg steps, 8 m range, sigma 0.01 m, 1 mm
  resolution, no return = +inf; mounted 0.12 m ahead of the base centre, 0.30 m high.
- PTZ camera: 640x480, f = 525 px at zoom 1 (HFOV 63 deg), zoom 1-10x, on a mast 1.10 m high; at most
  ``image_rate_hz`` snapshots per second, aimed at the nearest label in reach of the camera (new labels first,
  then a second view 0.5 m away from the first; pointing error 0.5 deg) and zoomed to ~5 px per QR module;
  rendered (segno code warped by the true homography over a floor/wall background, lighting gain 0.75-1.15
  with a gradient, blur sigma 0.4-0.8 px, noise 2 grey levels, JPEG quality 55). A label is readable when
  fully in the image, facing the camera within 60 deg, not occluded, and at >= 3 px per module.

Topics of the log (log time = publish time = header stamp, sensor time starting at ``T0_NS``):

- ``/odom`` nav_msgs/msg/Odometry 20 Hz, frame ``odom``, child ``base_link``, pose covariance (x, y, yaw
  entries; 1e6 for z, roll, pitch), twist with covariance.
- ``/compass`` sensor_msgs/msg/Imu 10 Hz, yaw quaternion in the map-aligned magnetic frame,
  orientation_covariance[8] = sigma^2, angular_velocity/linear_acceleration_covariance[0] = -1.
- ``/scan`` sensor_msgs/msg/LaserScan 5 Hz, frame ``laser``.
- ``/camera/image/compressed`` sensor_msgs/msg/CompressedImage (``jpeg``), frame ``camera_optical``, and
  ``/camera/camera_info`` sensor_msgs/msg/CameraInfo with the same stamp (K changes with zoom, D = 0).
- ``/tf_static`` tf2_msgs/msg/TFMessage: base_link->laser, base_link->ptz_base; ``/tf``:
  ptz_base->camera_optical at each image (pan/tilt, zero translation).
- ``/tags`` holoslam_msgs/msg/TagDetectionArray per image: payload + corners (x0, y0, ..., x3, y3) in the
  code's order TL, TR, BR, BL, the true projection plus 0.3 px noise, for each readable label.
- ``/ground_truth/pose`` geometry_msgs/msg/PoseStamped (frame ``map``) at each odometry stamp;
  ``/ground_truth/world`` std_msgs/msg/String once (``world_to_json``); ``/ground_truth/visible``
  std_msgs/msg/String per image: ``{"stamp_ns": ..., "ids": [...]}``.
- metadata record ``holoslam``: the SimConfig fields, duration_s and t0_ns.
"""

from holoslam.sim.core import T0_NS, SimConfig, SimulatedRun, simulate_household, simulate_to_file

__all__ = ["SimConfig", "SimulatedRun", "simulate_household", "simulate_to_file", "T0_NS"]
