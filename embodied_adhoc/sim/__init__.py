"""MuJoCo worlds: scene composition, the container robot (wheels, encoders, odometry, RFID, lidar), the human
walker, localisation, and the arenas with their map metadata (docs/sim.md, docs/arenas.md).

Where this layer sits and what it may import: docs/layout.md."""
