//! A release for both image slots in one file.
//!
//! An F446RE application runs in place from slot A or slot B and is linked for one of them,
//! so a release is two signed images, one per slot. A file may hold one image, or the two
//! one after the other: each image's header gives its length (512 + payload + 64), so the
//! next one starts right after, and nothing else is needed to tell them apart. The tester
//! picks the image for the slot the ECU is about to write; the ECU only ever sees one.

use core::fmt;

use crate::{ImageError, ImageHeader, ImageSlot};

/// Images a set holds at most: one per slot.
pub const MAX_SET_IMAGES: usize = 2;

/// One image of a file: its bytes and its parsed header.
pub type SetImage<'a> = (&'a [u8], ImageHeader);

/// The images of a file, in file order, with their headers (parsed, not yet verified:
/// the ECU verifies the one it receives).
#[derive(Debug, Clone, Copy)]
pub struct ImageSet<'a> {
    first: SetImage<'a>,
    second: Option<SetImage<'a>>,
}

/// Why a file is not an image or a set of images.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum SetError {
    /// The file is empty.
    Empty,
    /// Image `index` (0 first) of the file is not an image.
    Image {
        /// Which image of the file.
        index: usize,
        /// What is wrong with it.
        error: ImageError,
    },
    /// More than one image per slot: bytes follow the second image.
    TooMany,
    /// Both images are linked for the same slot.
    SameSlot(ImageSlot),
}

impl fmt::Display for SetError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            SetError::Empty => f.write_str("the image file is empty"),
            SetError::Image { index: 0, error } => write!(f, "{error}"),
            SetError::Image { index, error } => {
                write!(f, "image {} of the file: {error}", index + 1)
            }
            SetError::TooMany => write!(
                f,
                "bytes follow the second image: a file holds at most {MAX_SET_IMAGES} images, one per slot"
            ),
            SetError::SameSlot(slot) => write!(
                f,
                "both images of the file are linked for slot {}: a set holds one image per slot",
                slot.letter()
            ),
        }
    }
}

impl core::error::Error for SetError {}

impl<'a> ImageSet<'a> {
    /// The images of `file`: one, or two for different slots, back to back.
    pub fn parse(file: &'a [u8]) -> Result<Self, SetError> {
        if file.is_empty() {
            return Err(SetError::Empty);
        }
        let (first, rest) = split_image(file, 0)?;
        if rest.is_empty() {
            return Ok(ImageSet {
                first,
                second: None,
            });
        }
        let (second, rest) = split_image(rest, 1)?;
        if !rest.is_empty() {
            return Err(SetError::TooMany);
        }
        if let Some(slot) = first.1.slot().filter(|&slot| second.1.slot() == Some(slot)) {
            return Err(SetError::SameSlot(slot));
        }
        Ok(ImageSet {
            first,
            second: Some(second),
        })
    }

    /// The images with their headers, in file order.
    pub fn iter(&self) -> impl Iterator<Item = (&'a [u8], &ImageHeader)> + '_ {
        core::iter::once(&self.first)
            .chain(self.second.as_ref())
            .map(|(image, header)| (*image, header))
    }

    /// How many images the file holds (1 or 2).
    pub fn len(&self) -> usize {
        1 + usize::from(self.second.is_some())
    }

    /// Always false: a set holds at least one image.
    pub fn is_empty(&self) -> bool {
        false
    }

    /// The image linked for `slot`, with its header.
    pub fn for_slot(&self, slot: ImageSlot) -> Option<SetImage<'a>> {
        core::iter::once(self.first)
            .chain(self.second)
            .find(|(_, header)| header.slot() == Some(slot))
    }

    /// The first image's header (what a set is "of": ECU, version, variant).
    pub fn first(&self) -> ImageHeader {
        self.first.1
    }

    /// The first image's bytes.
    pub fn first_image(&self) -> &'a [u8] {
        self.first.0
    }
}

/// The image at the start of `bytes` (image `index` of the file) and what follows it.
fn split_image(bytes: &[u8], index: usize) -> Result<(SetImage<'_>, &[u8]), SetError> {
    let header = ImageHeader::parse(bytes).map_err(|error| SetError::Image { index, error })?;
    let len = header.image_len();
    if len > bytes.len() as u64 {
        return Err(SetError::Image {
            index,
            error: ImageError::Truncated {
                expected: len,
                found: bytes.len() as u64,
            },
        });
    }
    let (image, rest) = bytes.split_at(len as usize);
    Ok(((image, header), rest))
}

#[cfg(all(test, feature = "std"))]
mod tests {
    use super::*;
    use crate::{dev, ImageBuilder, SigningKey, Version};

    fn image(slot: ImageSlot, version: Version) -> Vec<u8> {
        let mut builder = ImageBuilder::new(8, version, vec![0x5A; 100]);
        builder.load_address = slot.vector_table();
        builder
            .sign(&SigningKey::from_seed(dev::SIGNING_SEED))
            .expect("an image")
    }

    #[test]
    fn one_image_is_a_set_of_one() {
        let a = image(ImageSlot::A, Version::new(1, 0, 0));
        let set = ImageSet::parse(&a).expect("one image");
        assert_eq!(set.len(), 1);
        assert_eq!(
            set.for_slot(ImageSlot::A).map(|(i, _)| i),
            Some(a.as_slice())
        );
        assert_eq!(set.for_slot(ImageSlot::B), None);
        assert_eq!(set.first().version, Version::new(1, 0, 0));
    }

    #[test]
    fn two_images_split_by_their_headers() {
        let a = image(ImageSlot::A, Version::new(1, 2, 0));
        let b = image(ImageSlot::B, Version::new(1, 2, 0));
        let file = [b.clone(), a.clone()].concat();
        let set = ImageSet::parse(&file).expect("a set");
        assert_eq!(set.len(), 2);
        assert_eq!(
            set.for_slot(ImageSlot::A).map(|(i, _)| i),
            Some(a.as_slice())
        );
        assert_eq!(
            set.for_slot(ImageSlot::B).map(|(i, _)| i),
            Some(b.as_slice())
        );
        assert_eq!(set.iter().count(), 2);
        assert_eq!(set.first().slot(), Some(ImageSlot::B));
    }

    #[test]
    fn broken_sets_are_refused_with_what_is_wrong() {
        let a = image(ImageSlot::A, Version::new(1, 0, 0));
        let b = image(ImageSlot::B, Version::new(1, 0, 0));
        assert_eq!(ImageSet::parse(&[]).err(), Some(SetError::Empty));
        let twice_a = [a.clone(), a.clone()].concat();
        assert_eq!(
            ImageSet::parse(&twice_a).err(),
            Some(SetError::SameSlot(ImageSlot::A))
        );
        let three = [a.clone(), b.clone(), a.clone()].concat();
        assert_eq!(ImageSet::parse(&three).err(), Some(SetError::TooMany));
        let cut = [a.clone(), b[..b.len() - 1].to_vec()].concat();
        let error = ImageSet::parse(&cut).expect_err("truncated second image");
        assert!(matches!(
            error,
            SetError::Image {
                index: 1,
                error: ImageError::Truncated { .. }
            }
        ));
        assert!(
            error.to_string().starts_with("image 2 of the file: "),
            "{error}"
        );
        let junk = [a.clone(), b"junk".to_vec()].concat();
        assert!(matches!(
            ImageSet::parse(&junk),
            Err(SetError::Image { index: 1, .. })
        ));
        let error = ImageSet::parse(&[b'x'; 600]).expect_err("junk");
        assert!(
            error.to_string().starts_with("not an AutoPlug image"),
            "{error}"
        );
    }
}
