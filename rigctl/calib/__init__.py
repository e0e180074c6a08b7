"""Calibration of the whole array: inputs, corner detection, joint solve, checks, report and exports."""

# a plain chessboard's square side, in the unit the calibration is to be in (no unit is stated: metres, millimetres,
# or 1 for one square): 0.1 mm in metres to 1 m in millimetres, the bounds a board file's square_m is held to in
# either unit. Beyond them the solve ends in OpenCV's assertion (1e300) or finds the points at one place (1e-300).
CHESSBOARD_SQUARE = (1e-4, 1e3)
# a plain chessboard's inner corners per side: OpenCV finds none on fewer than 3, and past 100 (10,000 corners, a
# board of ChArUco's largest 40 squares is 39) a board file's 10**9 asked for exabytes of corner coordinates
CHESSBOARD_CORNERS = (3, 100)
