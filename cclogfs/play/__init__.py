"""`cclog play`: a store's messages at their recorded pace (`pace`), published on ROS 1
topics with their recorded types (`ros1`) or served to the Foxglove app (`foxglove`)."""
