import pytest

from gcs.link.budget import compute_budget, control_streams, frame_bytes, suggest_fixes


def test_frame_sizes_of_design_notes():
    assert frame_bytes("SET_ATTITUDE_TARGET") == 51
    assert frame_bytes("ATTITUDE") == 40 and frame_bytes("LOCAL_POSITION_NED") == 40
    assert frame_bytes("ATTITUDE", signed=True) == 53
    with pytest.raises(ValueError):
        frame_bytes("NOT_A_MESSAGE")


def test_100_hz_full_state_does_not_fit_57600_and_fits_115200():
    b = compute_budget(control_streams(100.0), 57600)
    assert not b.fits
    assert b.capacity_bytes_s == 5760
    assert b.up_bytes_s / 5760 > 0.88  # SET_ATTITUDE_TARGET alone is 88 % of the link
    fixes = suggest_fixes(b, 100.0)
    assert any("--baud 115200" in f for f in fixes)
    assert compute_budget(control_streams(100.0), 115200).fits


def test_half_duplex_radio_with_ecc_is_checked():
    b = compute_budget(control_streams(100.0), 115200, air_rate_bps=64000, ecc=True)
    assert b.air_capacity_bytes_s == 4000 and not b.fits
