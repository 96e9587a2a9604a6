//! The overlay draws each mark where it is asked to, in its colour, and nothing elsewhere.

use skydome::formats::PixelPoint;
use skydome::image::{Circle, RgbImage};
use skydome::overlay::*;

#[test]
fn overlay_draws_each_mark_at_its_position_in_its_colour() {
    let mut img = RgbImage::<u8>::new(400, 300);
    let marks = OverlayMarks {
        visible: Some(Circle {
            cx: 200.5,
            cy: 150.5,
            r: 140.0,
        }),
        horizon: Some(Circle {
            cx: 200.5,
            cy: 150.5,
            r: 100.0,
        }),
        north: Some(PixelPoint { x: 200.5, y: 50.5 }),
        sun: Some(PixelPoint { x: 260.5, y: 120.5 }),
    };
    draw_overlay(&mut img, &marks);
    assert_eq!(img.pixel(200 + 140, 150), VISIBLE_COLOUR);
    assert_eq!(img.pixel(200 - 100, 150), HORIZON_COLOUR);
    assert_eq!(img.pixel(200, 50), NORTH_COLOUR);
    // Pixel centres sit at +0.5, so these marks are centred on pixels.
    // Sun ring radius is 2 × scale (scale = 3 px here) = 6 px.
    assert_eq!(img.pixel(260 + 6, 120), SUN_COLOUR);
    assert_eq!(img.pixel(260, 120), [0, 0, 0], "ring, not a disc");
    // Far from every mark nothing changes.
    assert_eq!(img.pixel(200, 150), [0, 0, 0]);
    assert_eq!(img.pixel(5, 5), [0, 0, 0]);
    let touched = img.pixels().filter(|p| *p != [0, 0, 0]).count();
    // Two 1-px rings (~2π·240 px) plus two small marks, with anti-aliasing fringes.
    assert!(touched > 1500 && touched < 4000, "{touched}");
}

#[test]
fn overlay_ignores_marks_outside_the_image_or_not_finite() {
    let mut img = RgbImage::<u8>::new(50, 40);
    draw_overlay(
        &mut img,
        &OverlayMarks {
            visible: Some(Circle {
                cx: f64::NAN,
                cy: 0.0,
                r: 10.0,
            }),
            horizon: Some(Circle {
                cx: 1e9,
                cy: -1e9,
                r: 5.0,
            }),
            north: Some(PixelPoint { x: -100.0, y: 20.0 }),
            sun: Some(PixelPoint {
                x: f64::INFINITY,
                y: 1.0,
            }),
        },
    );
    assert!(img.pixels().all(|p| p == [0, 0, 0]));
}
