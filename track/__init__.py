"""OpenCV tracker: video to sub-pixel ball centroids in table metres."""
