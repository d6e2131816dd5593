"""ROS 2 adapters: topics, QoS and message builders, node parameters, the node runtime,
message authentication, the DDS environment, and the bag writer.
"""
