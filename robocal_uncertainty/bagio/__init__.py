"""Campaigns as ROS 2 recordings: single MCAP files and rosbag2 directories."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.bagio.campaign_mcap import CampaignRecorder, read_campaign, write_campaign
    from robocal_uncertainty.bagio.point_cloud2 import read_point_cloud2

__all__ = ["CampaignRecorder", "read_campaign", "read_point_cloud2", "write_campaign"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
