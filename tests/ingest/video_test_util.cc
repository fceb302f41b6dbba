#include "video_test_util.h"

extern "C" {
#include <libavcodec/avcodec.h>
#include <libavformat/avformat.h>
#include <libavutil/opt.h>
#include <libswscale/swscale.h>
}

#include <cmath>
#include <fstream>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>
#include <vector>

namespace fmv3d::test {

cv::Mat RandomTexture(int width, int height, unsigned seed) {
  std::mt19937 rng(seed);
  cv::Mat acc(height, width, CV_32FC3, cv::Scalar::all(0));
  // Noise at several scales: fine detail for sharpness, coarse for large-scale structure.
  for (int scale : {2, 6, 24}) {
    cv::Mat small(std::max(2, height / scale), std::max(2, width / scale), CV_32FC3);
    cv::randu(small, cv::Scalar::all(0), cv::Scalar::all(1));
    cv::Mat up;
    cv::resize(small, up, acc.size(), 0, 0, cv::INTER_CUBIC);
    acc += up * (scale == 2 ? 0.35 : 0.5);
  }
  cv::Mat img;
  acc.convertTo(img, CV_8UC3, 255.0 / 1.35, -40);
  std::uniform_int_distribution<int> ux(0, width - 1), uy(0, height - 1), ur(4, 40), uc(0, 255);
  for (int i = 0; i < width * height / 1500; ++i) {
    const int b = uc(rng), g = uc(rng), r = uc(rng);  // one draw per declarator: in order on every compiler
    const cv::Scalar col(b, g, r);
    const int x = ux(rng), y = uy(rng), size = ur(rng);
    if (i % 2)
      cv::rectangle(img, cv::Rect(x, y, size, ur(rng)), col, cv::FILLED);
    else
      cv::circle(img, cv::Point(x, y), size / 2, col, cv::FILLED, cv::LINE_AA);
  }
  return img;
}

cv::Mat ViewOf(const cv::Mat& texture, cv::Size out, double cx, double cy, double zoom, double angle) {
  // Output pixel p samples texture at c + R(angle) (p - centre) / zoom.
  const double c = std::cos(angle) * zoom, s = std::sin(angle) * zoom;
  // Inverse map texture → output: p = centre + zoom R(-angle) (t - c).
  cv::Mat M = (cv::Mat_<double>(2, 3) << c, s, out.width / 2.0 - (c * cx + s * cy), -s, c,
               out.height / 2.0 - (-s * cx + c * cy));
  cv::Mat view;
  cv::warpAffine(texture, view, M, out, cv::INTER_LINEAR, cv::BORDER_REFLECT);
  return view;
}

void EncodeVideo(const std::filesystem::path& path, int n, double fps, const std::function<cv::Mat(int)>& frame_fn,
                 const std::string& codec_name, int gop, int sar_num, int sar_den) {
  auto fail = [&](const std::string& what) { throw std::runtime_error("EncodeVideo " + path.string() + ": " + what); };
  const cv::Mat first = frame_fn(0);
  AVFormatContext* fmt = nullptr;
  if (avformat_alloc_output_context2(&fmt, nullptr, nullptr, path.c_str()) < 0 || !fmt) fail("no muxer");
  const AVCodec* codec = avcodec_find_encoder_by_name(codec_name.c_str());
  if (!codec) fail("no encoder " + codec_name);
  AVStream* st = avformat_new_stream(fmt, nullptr);
  AVCodecContext* enc = avcodec_alloc_context3(codec);
  enc->width = first.cols;
  enc->height = first.rows;
  const AVRational rate = av_d2q(fps, 100000);
  enc->time_base = av_inv_q(rate);
  enc->framerate = rate;
  enc->gop_size = gop;
  enc->sample_aspect_ratio = AVRational{sar_num, sar_den};
  enc->max_b_frames = codec_name == "mpeg2video" ? 2 : 0;  // B-frames: decode-order ≠ output order
  enc->pix_fmt = codec_name == "gif"     ? AV_PIX_FMT_RGB8
                 : codec_name == "mjpeg" ? AV_PIX_FMT_YUVJ420P
                 : codec_name == "ffv1"  ? AV_PIX_FMT_YUV444P
                                         : AV_PIX_FMT_YUV420P;
  if (codec_name == "mpeg4" || codec_name == "mpeg2video" || codec_name == "mjpeg") {
    // Constant quality: frame sizes stay even (truncation tests cut at a predictable frame) and sharp.
    enc->flags |= AV_CODEC_FLAG_QSCALE;
    enc->global_quality = FF_QP2LAMBDA * 3;
  }
  enc->thread_count = 1;
  if (codec_name == "libx264") av_opt_set(enc->priv_data, "preset", "ultrafast", 0);
  if (fmt->oformat->flags & AVFMT_GLOBALHEADER) enc->flags |= AV_CODEC_FLAG_GLOBAL_HEADER;
  if (avcodec_open2(enc, codec, nullptr) < 0) fail("cannot open encoder");
  avcodec_parameters_from_context(st->codecpar, enc);
  st->time_base = enc->time_base;
  st->sample_aspect_ratio = enc->sample_aspect_ratio;
  if (!(fmt->oformat->flags & AVFMT_NOFILE) && avio_open(&fmt->pb, path.c_str(), AVIO_FLAG_WRITE) < 0)
    fail("cannot open output");
  if (avformat_write_header(fmt, nullptr) < 0) fail("cannot write header");
  AVFrame* fr = av_frame_alloc();
  fr->format = enc->pix_fmt;
  fr->width = enc->width;
  fr->height = enc->height;
  av_frame_get_buffer(fr, 0);
  SwsContext* sws = sws_getContext(enc->width, enc->height, AV_PIX_FMT_BGR24, enc->width, enc->height, enc->pix_fmt,
                                   SWS_BICUBIC, nullptr, nullptr, nullptr);
  AVPacket* pkt = av_packet_alloc();
  auto drain = [&] {
    while (avcodec_receive_packet(enc, pkt) == 0) {
      if (pkt->duration <= 0) pkt->duration = 1;  // one frame; else mp4 edit lists drop the last one
      av_packet_rescale_ts(pkt, enc->time_base, st->time_base);
      pkt->stream_index = st->index;
      av_interleaved_write_frame(fmt, pkt);
    }
  };
  for (int i = 0; i < n; ++i) {
    const cv::Mat img = i == 0 ? first : frame_fn(i);
    if (img.size() != first.size() || img.type() != CV_8UC3) fail("frame size/type changed");
    av_frame_make_writable(fr);
    const uint8_t* src[1] = {img.data};
    const int stride[1] = {static_cast<int>(img.step[0])};
    sws_scale(sws, src, stride, 0, img.rows, fr->data, fr->linesize);
    fr->pts = i;
    fr->quality = enc->global_quality;
    if (avcodec_send_frame(enc, fr) < 0) fail("encode failed");
    drain();
  }
  avcodec_send_frame(enc, nullptr);
  drain();
  av_write_trailer(fmt);
  av_packet_free(&pkt);
  sws_freeContext(sws);
  av_frame_free(&fr);
  avcodec_free_context(&enc);
  if (!(fmt->oformat->flags & AVFMT_NOFILE)) avio_closep(&fmt->pb);
  avformat_free_context(fmt);
}

void TruncateCopy(const std::filesystem::path& from, const std::filesystem::path& to, double fraction) {
  std::ifstream in(from, std::ios::binary);
  std::vector<char> bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  bytes.resize(static_cast<size_t>(bytes.size() * fraction));
  std::ofstream out(to, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

}  // namespace fmv3d::test
