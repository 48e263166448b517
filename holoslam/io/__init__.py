"""The only package that touches files and formats: MCAP / rosbag2 logs, g2o, TUM, map_server grids,
GraphML / JSON graphs, datasets. Everything here returns holoslam records or raises ``IngestError``."""
