"""Message plumbing shared by every node: PointCloud2 codec, QoS, topic names, node main().

Modules:
    topics: default topic names and frame ids.
    qos: the graph's QoS profiles.
    fields: structured dtypes of the graph's PointCloud2 layouts.
    pointcloud: vectorised PointCloud2 <-> numpy codec.
    node_main: the shared ``main()`` (SIGINT/SIGTERM, clean shutdown).
    params: declare ROS parameters from a dict of defaults with descriptors.
    testing: pytest harness for graph tests (processes, domains, waits).
"""
