"""Campaigns as ROS 2 recordings: single MCAP files and rosbag2 directories."""

from typing import TYPE_CHECKING

from robocal_uncertainty._lazy import lazy_exports

if TYPE_CHECKING:
    from robocal_uncertainty.bagio.campaign_mcap import CampaignRecorder, read_campaign, write_campaign

__all__ = ["CampaignRecorder", "read_campaign", "write_campaign"]
__getattr__, __dir__ = lazy_exports(__name__, __file__, __all__)
